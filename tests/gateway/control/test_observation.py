"""A control loop's observation from what a robot publishes: joints taken by name from a
real sensor_msgs/JointState, and states the policy could not be sent refused: a value that
is finite as float64 but not as float32 (the wire's type), a joint named twice."""

from __future__ import annotations

import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from oricf.gateway.control.observation import MissingState, Observation, StatePart

FLOAT32_MAX = float(np.finfo(np.float32).max)


def joints_observation() -> Observation:
    part = StatePart(topic="/arm/joint_states", type="sensor_msgs/JointState",
                     fields=["position", "velocity"], joints=["j1", "j2", "j3"])
    return Observation([part], 6, max_age_ms=1e6)


def array_observation() -> Observation:
    part = StatePart(topic="/arm/state", type="std_msgs/Float64MultiArray", size=3)
    return Observation([part], 3, max_age_ms=1e6)


def test_joints_are_taken_by_name_whatever_order_the_driver_sends() -> None:
    observation = joints_observation()
    observation.take(0, JointState(name=["j3", "j1", "j2"], position=[3.0, 1.0, 2.0],
                                   velocity=[30.0, 10.0, 20.0]), received_ns=1)
    assert observation.assemble(2).state.tolist() == [1.0, 2.0, 3.0, 10.0, 20.0, 30.0]


def test_a_joint_state_that_names_a_joint_twice_is_refused() -> None:
    """Which of j1's values is j1's? Neither is taken (the NaN in the first j1 would have
    been hidden by the second), and the last good state is not used on either."""
    observation = joints_observation()
    observation.take(0, JointState(name=["j1", "j2", "j3"], position=[1.0, 2.0, 3.0],
                                   velocity=[0.0, 0.0, 0.0]), received_ns=1)
    ambiguous = JointState(name=["j1", "j1", "j2", "j3"], position=[np.nan, 1.0, 2.0, 3.0],
                           velocity=[0.0, 0.0, 0.0, 0.0])
    with pytest.raises(MissingState, match="joint 'j1' is named twice"):
        observation.take(0, ambiguous, received_ns=2)
    assert observation.refused == 1
    with pytest.raises(MissingState, match="nothing received"):
        observation.assemble(3)


@pytest.mark.parametrize("value", [1e300, -1e300, 3.5e38, 1e39, np.nan, np.inf])
def test_a_state_not_finite_as_float32_is_refused_as_it_arrives(value: float) -> None:
    """The policy is sent float32: 1e300, finite as float64, would arrive as infinity. The
    message is refused naming its topic, and the last good state is not used on."""
    observation = array_observation()
    observation.take(0, Float64MultiArray(data=[0.1, 0.1, 0.2]), received_ns=1)
    with pytest.raises(MissingState,
                       match=r"^/arm/state: value\[1\] is .*: not finite as float32"):
        observation.take(0, Float64MultiArray(data=[0.1, value, 0.2]), received_ns=2)
    assert observation.refused == 1
    with pytest.raises(MissingState, match="nothing received"):
        observation.assemble(3)


def test_the_largest_float32_values_are_taken() -> None:
    observation = array_observation()
    observation.take(0, Float64MultiArray(data=[FLOAT32_MAX, -FLOAT32_MAX, 1e-300]),
                     received_ns=1)
    sent = observation.assemble(2).state.astype(np.float32)
    assert np.isfinite(sent).all()
