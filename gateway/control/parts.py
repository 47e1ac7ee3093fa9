"""The parts of a control loop's observation and the robot's message types they read: each
type one entry, a state part's in `STATE_TYPES` (how its message gives values, how many),
a camera's in `CAMERA_TYPES` (its message as the frame it carries).

    state:
      - {topic: /arm/joint_states, type: sensor_msgs/JointState,
         fields: [position, velocity], joints: [shoulder, elbow]}   # in this order
      - {topic: /arm/goal, type: std_msgs/Float64MultiArray, size: 7}
    images:
      - {name: wrist, topic: /arm/wrist/image_raw, type: sensor_msgs/Image}

A JointState part takes the named joints' values (by name, so a driver that orders them
otherwise is read right; a message that names a joint twice is refused: which of its values
would be the joint's?), each field in turn; without `joints`, the message's own order. A
camera's frame is checked (sizes, encoding), not decoded: the policy decodes it, wherever it
runs. The messages are rclpy's, or anything with the same fields.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

import numpy as np
from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.gateway.values import Frame, compressed_frame, raw_frame

JointField = Literal["position", "velocity", "effort"]
CAMERA_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"  # as a policy declares its cameras


class StatePart(Schema):
    topic: str = Field(description="a ROS topic")
    type: str = Field(description="the message type: one of STATE_TYPES")
    fields: list[JointField] = Field(["position"], min_length=1,
                                     description="JointState: the fields taken, in order")
    joints: list[str] | None = Field(None, max_length=256,
                                     description="JointState: the joints taken, by name")
    size: int | None = Field(None, ge=1, le=4096,
                             description="Float64MultiArray: values expected")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        if type_ not in STATE_TYPES:
            raise ValueError(f"a state type: {', '.join(STATE_TYPES)}")
        return type_

    @model_validator(mode="after")
    def _consistent(self) -> StatePart:
        if self.joints is not None and not STATE_TYPES[self.type].names_joints:
            named = [name for name, type_ in STATE_TYPES.items() if type_.names_joints]
            raise ValueError(f"joints: only for {', '.join(named)}")
        return self


class CameraPart(Schema):
    """One camera of the policy: the topic its images come on."""

    name: str = Field(pattern=CAMERA_NAME, description="the policy's camera it feeds")
    topic: str = Field(description="a ROS topic")
    type: str = Field("sensor_msgs/Image", description="one of CAMERA_TYPES")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        if type_ not in CAMERA_TYPES:
            raise ValueError(f"a camera type: {', '.join(CAMERA_TYPES)}")
        return type_


class StateType(Protocol):
    """A state part's message type."""

    names_joints: bool   # its values are named joints (a part may pick them: `joints`)

    def values(self, part: StatePart, msg: Any) -> np.ndarray:
        """The part's values from one message (ValueError naming what is wrong)."""

    def size(self, part: StatePart) -> int | None:
        """The values a message gives, where the part's settings say."""


class Float64MultiArray:
    names_joints = False

    def values(self, part: StatePart, msg: Any) -> np.ndarray:
        values = np.asarray(msg.data, np.float64)
        if part.size is not None and values.size != part.size:
            raise ValueError(f"{values.size} values, not {part.size}")
        return values

    def size(self, part: StatePart) -> int | None:
        return part.size


class JointState:
    names_joints = True

    def values(self, part: StatePart, msg: Any) -> np.ndarray:
        names = list(msg.name)
        taken = None if part.joints is None else joint_positions(part.joints, names)
        rows = []
        for name in part.fields:
            column = np.asarray(getattr(msg, name), np.float64)
            if taken is not None:
                if column.size != len(names):
                    raise ValueError(f"{name} has {column.size} values for {len(names)} "
                                     f"joints")
                column = column[taken]
            rows.append(column)
        return np.concatenate(rows)

    def size(self, part: StatePart) -> int | None:
        return None if part.joints is None else len(part.joints) * len(part.fields)


STATE_TYPES: dict[str, StateType] = {
    "sensor_msgs/JointState": JointState(),
    "std_msgs/Float64MultiArray": Float64MultiArray(),
}


class CameraType(Protocol):
    def frame(self, msg: Any) -> Frame:
        """The frame a camera's message carries (InvalidInput or ValueError if it is not
        one)."""


class Image:
    def frame(self, msg: Any) -> Frame:
        return raw_frame(bytes(msg.data), str(msg.encoding), int(msg.width), int(msg.height),
                         int(msg.step))


class CompressedImage:
    def frame(self, msg: Any) -> Frame:
        return compressed_frame(bytes(msg.data), str(msg.format))


CAMERA_TYPES: dict[str, CameraType] = {
    "sensor_msgs/Image": Image(),
    "sensor_msgs/CompressedImage": CompressedImage(),
}


def values_of(part: StatePart, msg: Any) -> np.ndarray:
    """The part's values from one message (ValueError naming what is wrong)."""
    return STATE_TYPES[part.type].values(part, msg)


def camera_frame(type_: str, msg: Any) -> Frame:
    """A camera's message as the frame it carries (checked: sizes, encoding), not decoded."""
    return CAMERA_TYPES[type_].frame(msg)


def joint_positions(joints: list[str], names: list[str]) -> list[int]:
    """Where each of `joints` is among a JointState's names, or ValueError: one is absent,
    or a name is given twice (which of its values would be the joint's?)."""
    index: dict[str, int] = {}
    for i, joint in enumerate(names):
        if index.setdefault(joint, i) != i:
            raise ValueError(f"joint {joint[:100]!r} is named twice (joints: "
                             f"{', '.join(names)[:200]})")
    absent = [joint for joint in joints if joint not in index]
    if absent:
        raise ValueError(f"no joint {', '.join(absent)[:200]} (joints: "
                         f"{', '.join(names)[:200]})")
    return [index[joint] for joint in joints]
