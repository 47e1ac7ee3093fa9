"""The robot's message types a control loop reads: each one entry of the table of types
(oricf.gateway.topics.types) that may be a state part or a camera, so a new one is taken by
the settings and the observation alike."""

from __future__ import annotations

from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pytest
from pydantic import ValidationError

from oricf.gateway.control.observation import Observation
from oricf.gateway.control.parts import CameraPart, StatePart
from oricf.gateway.topics.types import RosType, register, unregister

POINT32 = RosType("geometry_msgs/Point32", "float32 x\nfloat32 y\nfloat32 z\n",
                  frozenset({"state"}), lambda msg: np.array([msg.x, msg.y, msg.z]))


@pytest.fixture
def point32() -> Iterator[None]:
    """geometry_msgs/Point32 as three state values, a type only this test knows."""
    register(POINT32)
    yield
    unregister(POINT32.name)


@pytest.mark.usefixtures("point32")
def test_a_state_type_added_to_the_table_is_read_into_the_observation() -> None:
    part = StatePart(topic="/arm/goal", type="geometry_msgs/Point32", size=3)
    observation = Observation([part], part.expected() or -1, max_age_ms=1e6)
    observation.take(0, SimpleNamespace(x=1.0, y=2.0, z=3.0), received_ns=1)
    assert observation.assemble(2).state.tolist() == [1.0, 2.0, 3.0]


def test_a_type_not_in_the_tables_is_refused_naming_those_that_are() -> None:
    with pytest.raises(ValidationError, match="a state type: sensor_msgs/JointState, "
                                              "std_msgs/Float64MultiArray"):
        StatePart(topic="/arm/goal", type="geometry_msgs/Vector3")
    with pytest.raises(ValidationError, match="a camera type: sensor_msgs/Image, "
                                              "sensor_msgs/CompressedImage"):
        CameraPart(name="wrist", topic="/arm/wrist", type="sensor_msgs/PointCloud2")
    with pytest.raises(ValidationError, match="joints: only for sensor_msgs/JointState"):
        StatePart(topic="/arm/goal", type="std_msgs/Float64MultiArray", joints=["a"])
