"""A control loop's observation: the newest message of each of its state topics, each part
no older than `max_age_ms`, joined into one state vector in the order the parts are listed.

    state:
      - {topic: /arm/joint_states, type: sensor_msgs/JointState,
         fields: [position, velocity], joints: [shoulder, elbow]}   # in this order
      - {topic: /arm/goal, type: std_msgs/Float64MultiArray}

A JointState part takes the named joints' values (by name, so a driver that orders them
otherwise is read right), each field in turn; without `joints`, the message's own order. A
part that has not arrived, is too old, has the wrong length or a value that is not finite
makes the observation missing: the loop then asks nothing and runs out what it has queued.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from oricf.config import Schema

StateType = Literal["sensor_msgs/JointState", "std_msgs/Float64MultiArray"]
JointField = Literal["position", "velocity", "effort"]


class StatePart(Schema):
    topic: str = Field(description="a ROS topic")
    type: StateType
    fields: list[JointField] = Field(["position"], min_length=1,
                                     description="JointState: the fields taken, in order")
    joints: list[str] | None = Field(None, max_length=256,
                                     description="JointState: the joints taken, by name")
    size: int | None = Field(None, ge=1, le=4096,
                             description="Float64MultiArray: values expected")

    @model_validator(mode="after")
    def _consistent(self) -> StatePart:
        if self.type != "sensor_msgs/JointState" and self.joints is not None:
            raise ValueError("joints: only for sensor_msgs/JointState")
        return self


class MissingState(Exception):
    """No observation now; the message says which part and why."""


@dataclass
class Latest:
    values: np.ndarray
    received_ns: int


def values_of(part: StatePart, msg: Any) -> np.ndarray:
    """The part's values from one message (ValueError naming what is wrong)."""
    if part.type == "std_msgs/Float64MultiArray":
        values = np.asarray(msg.data, np.float64)
        if part.size is not None and values.size != part.size:
            raise ValueError(f"{values.size} values, not {part.size}")
        return values
    names = list(msg.name)
    rows = []
    for name in part.fields:
        column = np.asarray(getattr(msg, name), np.float64)
        if part.joints is None:
            rows.append(column)
            continue
        if column.size != len(names):
            raise ValueError(f"{name} has {column.size} values for {len(names)} joints")
        index = {joint: i for i, joint in enumerate(names)}
        absent = [joint for joint in part.joints if joint not in index]
        if absent:
            raise ValueError(f"no joint {', '.join(absent)[:200]} (joints: "
                             f"{', '.join(names)[:200]})")
        rows.append(column[[index[joint] for joint in part.joints]])
    return np.concatenate(rows)


class Observation:
    """Thread-safe: message callbacks `take`, the loop's thread `assemble`s."""

    def __init__(self, parts: list[StatePart], size: int, max_age_ms: float) -> None:
        """`size`: the state's length, -1 when the parts do not say."""
        self.parts = parts
        self.size = size
        self.max_age_ns = int(max_age_ms * 1e6)
        self.refused = 0          # messages whose values could not be used
        self._latest: list[Latest | None] = [None] * len(parts)
        self._lock = threading.Lock()

    def take(self, index: int, msg: Any, received_ns: int | None = None) -> None:
        part = self.parts[index]
        try:
            values = values_of(part, msg)
        except (TypeError, ValueError, AttributeError) as exc:  # not what its type says
            with self._lock:
                self.refused += 1
                self._latest[index] = None  # the part's last good value is not used on
            raise MissingState(f"{part.topic}: {exc}") from None
        with self._lock:
            self._latest[index] = Latest(values, received_ns or time.monotonic_ns())

    def assemble(self, now_ns: int) -> tuple[np.ndarray, int]:
        """The state vector and the time its oldest part was received, or MissingState."""
        with self._lock:
            latest = list(self._latest)
        for part, got in zip(self.parts, latest, strict=True):
            if got is None:
                raise MissingState(f"{part.topic}: nothing received")
            age_ns = now_ns - got.received_ns
            if age_ns > self.max_age_ns:
                raise MissingState(f"{part.topic}: the newest message is {age_ns / 1e6:.0f} ms old "
                                   f"(max_age_ms {self.max_age_ns / 1e6:g})")
        state = np.concatenate([got.values for got in latest if got is not None])
        if self.size >= 0 and state.size != self.size:
            raise MissingState(f"the state parts give {state.size} values, the policy takes "
                               f"{self.size}")
        bad = np.flatnonzero(~np.isfinite(state))
        if bad.size:
            raise MissingState(f"state[{bad[0]}] is {state[bad[0]]}: not finite")
        oldest = min(got.received_ns for got in latest if got is not None)
        return state, oldest
