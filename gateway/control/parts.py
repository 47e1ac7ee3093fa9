"""The parts of a control loop's observation: its state parts and cameras, each reading the
robot's messages of a type the table of types (oricf.gateway.topics.types) lets it name
(`state`, `camera`), as the value that type's entry reads from them.

    state:
      - {topic: /arm/joint_states, type: sensor_msgs/JointState,
         fields: [position, velocity], joints: [shoulder, elbow]}   # in this order
      - {topic: /arm/goal, type: std_msgs/Float64MultiArray, size: 7}
    images:
      - {name: wrist, topic: /arm/wrist/image_raw, type: sensor_msgs/Image}

A state part whose type reads as numbers takes them all (`size`: as many as expected). One
whose type reads as joints (JointStates) takes the named joints' values (by name, so a
driver that orders them otherwise is read right; a message that names a joint twice is
refused: which of its values would be the joint's?), each field in turn; without `joints`,
the message's own order. A camera's frame is checked (sizes, encoding), not decoded: the
policy decodes it, wherever it runs. The messages are rclpy's, anything with the same fields,
or, for a type read serialized, its CDR bytes.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.gateway.topics import types
from oricf.gateway.topics.convert import JointStates
from oricf.gateway.values import Frame

JointField = Literal["position", "velocity", "effort"]
CAMERA_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"  # as a policy declares its cameras


class StatePart(Schema):
    topic: str = Field(description="a ROS topic")
    type: str = Field(description="the message type: a state type of "
                      "oricf.gateway.topics.types")
    fields: list[JointField] = Field(["position"], min_length=1,
                                     description="joints: the fields taken, in order")
    joints: list[str] | None = Field(None, max_length=256,
                                     description="joints: the joints taken, by name")
    size: int | None = Field(None, ge=1, le=4096,
                             description="numbers: values expected")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        return types.check(type_, "state", "a state type")

    @model_validator(mode="after")
    def _consistent(self) -> StatePart:
        if self.joints is not None and not names_joints(self.type):
            named = [name for name in types.names("state") if names_joints(name)]
            raise ValueError(f"joints: only for {', '.join(named)}")
        return self

    def expected(self) -> int | None:
        """The values a message gives, where the part's settings say."""
        if names_joints(self.type):
            return None if self.joints is None else len(self.joints) * len(self.fields)
        return self.size


class CameraPart(Schema):
    """One camera of the policy: the topic its images come on."""

    name: str = Field(pattern=CAMERA_NAME, description="the policy's camera it feeds")
    topic: str = Field(description="a ROS topic")
    type: str = Field(types.IMAGE, description="a camera type of oricf.gateway.topics.types")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        return types.check(type_, "camera", "a camera type")


def names_joints(type_: str) -> bool:
    """Its values are named joints: a part may pick them (`joints`)."""
    return types.ros_type(type_).names == "joints"


def values_of(part: StatePart, msg: Any) -> np.ndarray:
    """The part's values from one message (ValueError naming what is wrong)."""
    value = types.ros_type(part.type).value(msg)
    if isinstance(value, JointStates):
        return joint_values(part, value)
    values = np.asarray(value, np.float64)
    if part.size is not None and values.size != part.size:
        raise ValueError(f"{values.size} values, not {part.size}")
    return values


def joint_values(part: StatePart, states: JointStates) -> np.ndarray:
    """The part's fields of its joints (all, in the message's order, without `joints`)."""
    taken = None if part.joints is None else joint_positions(part.joints, states.names)
    rows = []
    for name in part.fields:
        column = getattr(states, name)
        if taken is not None:
            if column.size != len(states.names):
                raise ValueError(f"{name} has {column.size} values for {len(states.names)} "
                                 f"joints")
            column = column[taken]
        rows.append(column)
    return np.concatenate(rows)


def camera_frame(type_: str, msg: Any) -> Frame:
    """A camera's message (decoded, or serialized) as the frame it carries (checked: sizes,
    encoding), not decoded."""
    frame = types.ros_type(type_).value(msg)
    if not isinstance(frame, Frame):
        raise TypeError(f"{type_} carries no image")
    return frame


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
