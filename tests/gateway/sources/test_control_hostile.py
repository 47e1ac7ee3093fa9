"""The control input over real DDS against a hostile edge and a hostile robot: a policy
that answers with a million actions is refused as the answer arrives (a failed call, the
process's memory kept) and the loop goes on; a state of 1e300, finite as float64 and
infinite as the float32 the policy is sent, never reaches the policy; a JointState that names
a joint twice is refused. Each refusal is counted and logged."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.context import Context
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from oricf.v1 import policy_pb2
from tests.gateway.ros.gateway_node import wait_for
from tests.gateway.sources.test_control import Robot, control_config, running
from tests.support.hostile_edge import chunk, hostile_edge
from tests.support.peak_memory import peak_growth

MB = 1 << 20
ACTION = [0.1, 0.2, 0.3]
SAFE = [0.0, 0.0, 0.0]
STATE = [0.1] * 15


class Recording:
    """An honest edge's script: one action answers each observation, every one kept."""

    def __init__(self) -> None:
        self.seen: list[policy_pb2.Observation] = []

    def __call__(self, index: int, request: policy_pb2.Observation
                 ) -> policy_pb2.ActionChunk:
        self.seen.append(request)
        return chunk(request, [ACTION])


def test_an_answer_of_a_million_actions_is_refused_and_the_loop_goes_on(
        ros_context: Context) -> None:
    huge = policy_pb2.ActionChunk(action_dim=3, actions=np.zeros(3_000_000).tolist())  # 12 MB
    honest = Recording()

    def script(index: int, request: policy_pb2.Observation) -> policy_pb2.ActionChunk:
        return huge if index == 0 else honest(index, request)

    robot = Robot(ros_context)
    with hostile_edge(script) as (address, _):
        config = control_config(address, late="shift", request_at=1)
        with running(config, ros_context, robot) as run:
            source = run.source
            with peak_growth() as grown:
                robot.publishing = STATE
                wait_for(lambda: source.loop.counts.answers >= 5)
            assert grown() < 64 * MB, f"the peak rose {grown() / MB:.0f} MB"
            robot.wait_steady(ACTION)
            route = run.gateway.pipeline.routes["hopper"]
            assert route.stats.errors.get("RESOURCE_EXHAUSTED") == 1  # once: not retried
            assert source.loop.counts.failed >= 1


def test_a_state_beyond_float32_never_reaches_the_policy(
        ros_context: Context, caplog: pytest.LogCaptureFixture) -> None:
    robot = Robot(ros_context)
    honest = Recording()
    with hostile_edge(honest) as (address, _):
        config = control_config(address, late="shift", request_at=1)
        with running(config, ros_context, robot) as run:
            source = run.source
            robot.publishing = [1e300, *STATE[1:]]
            wait_for(lambda: source.observation.refused > 20)
            assert "state refused: /hopper/state: value[0] is 1e+300: not finite" in caplog.text
            robot.wait_steady(SAFE)
            assert not honest.seen
            robot.publishing = STATE
            robot.wait_steady(ACTION)
    assert honest.seen
    assert all(np.isfinite(np.asarray(seen.state)).all() for seen in honest.seen)


def test_a_joint_state_that_names_a_joint_twice_is_refused(
        ros_context: Context, caplog: pytest.LogCaptureFixture) -> None:
    """`j1, j1, j2, j3` with NaN in the first j1: neither j1 is taken (the second used to
    hide the first); the same joints named once are."""
    robot = Robot(ros_context)
    joints = robot.node.create_publisher(JointState, "/arm/joint_states", QoSProfile(depth=1))
    publishing = [JointState(name=["j1", "j1", "j2", "j3"], position=[np.nan, 0.1, 0.2, 0.3])]
    robot.node.create_timer(1 / 60, lambda: joints.publish(publishing[-1]))
    state = [{"topic": "/arm/joint_states", "type": "sensor_msgs/JointState",
              "joints": ["j1", "j2", "j3"]}]
    honest = Recording()
    with hostile_edge(honest) as (address, _):
        config = control_config(address, late="shift", request_at=1, state=state)
        with running(config, ros_context, robot) as run:
            source = run.source
            wait_for(lambda: source.observation.refused > 10)
            assert "state refused: /arm/joint_states: joint 'j1' is named twice" in caplog.text
            robot.wait_steady(SAFE)
            assert not honest.seen
            publishing.append(JointState(name=["j3", "j2", "j1"], position=[0.3, 0.2, 0.1]))
            robot.wait_steady(ACTION)
    np.testing.assert_allclose(honest.seen[-1].state, [0.1, 0.2, 0.3], rtol=1e-6)
