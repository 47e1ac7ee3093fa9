"""The robot's message types a control loop reads: each one entry of STATE_TYPES or
CAMERA_TYPES, so a new one is taken by the settings and the observation alike."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from oricf.gateway.control.observation import Observation
from oricf.gateway.control.parts import STATE_TYPES, CameraPart, StatePart


class Vector3:
    """geometry_msgs/Vector3 as three state values, a type only this test knows."""

    names_joints = False

    def values(self, part: StatePart, msg: Any) -> np.ndarray:
        return np.array([msg.x, msg.y, msg.z], np.float64)

    def size(self, part: StatePart) -> int | None:
        return 3


def test_a_state_type_added_to_the_table_is_read_into_the_observation(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(STATE_TYPES, "geometry_msgs/Vector3", Vector3())
    part = StatePart(topic="/arm/goal", type="geometry_msgs/Vector3")
    observation = Observation([part], STATE_TYPES[part.type].size(part) or -1, max_age_ms=1e6)
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
