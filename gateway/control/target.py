"""Where a control loop's actions go, and the policy they pass first: each action's values
within their bounds (clamped, or refused for the safe action), no faster than `max_rate_hz`,
and a deadman that sends the safe action when nothing was sent for `deadman_ms` (the loop's
thread stalled). The same rules an agent's commands pass (oricf.gateway.actuation), for a
vector of values a tick.

    target:
      topic: /arm/command
      type: trajectory_msgs/JointTrajectory     # or std_msgs/Float64MultiArray,
      joints: [shoulder, elbow, wrist]          #    geometry_msgs/Twist with fields:
      bounds: [[-1.5, 1.5], [-2, 2], [-1, 1]]   #    [linear.x, angular.z]
      beyond_bounds: clamp                      # or refuse: the safe action instead
      max_rate_hz: 100
      deadman_ms: 200
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.gateway.actuation.actuation import Deadman
from oricf.gateway.actuation.messages import fields_of
from oricf.gateway.topics import codec, types
from oricf.gateway.topics.convert import Action

log = logging.getLogger(__name__)

# A message as nested fields: the ROS layer fills its message (oricf.gateway.ros.messages).
Publish = Callable[[dict[str, Any]], None]


class ActionTargetConfig(Schema):
    topic: str = Field(description="the ROS topic the actions are published on")
    type: str = Field(types.NUMBERS, description="an action type of "
                      "oricf.gateway.topics.types")
    joints: list[str] | None = Field(None, max_length=256, description="JointTrajectory: "
                                     "the joint of each action value, in order")
    fields: list[str] | None = Field(None, description="Twist: the field of each action "
                                     "value, in order (linear.x, angular.z, ...)")
    time_from_start_ms: float = Field(0.0, ge=0, le=60_000, description="JointTrajectory: "
                                      "the point's time_from_start")
    bounds: list[tuple[float, float]] | None = Field(
        None, description="[min, max] of each action value (none: only finite values)")
    beyond_bounds: Literal["clamp", "refuse"] = "clamp"
    max_rate_hz: float = Field(1000.0, gt=0, le=10_000)
    deadman_ms: int | None = Field(None, ge=5, le=60_000, description="the safe action "
                                   "when none was sent for this long")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        return types.check(type_, "action", "an action type")

    @model_validator(mode="after")
    def _consistent(self) -> ActionTargetConfig:
        names = types.ros_type(self.type).names  # the key that names each value, if one
        for key in ("joints", "fields"):
            if (names == key) != (getattr(self, key) is not None):
                named = [t for t in types.names("action") if types.ros_type(t).names == key]
                raise ValueError(f"{key}: given with {', '.join(named)}, and only with it")
        unknown = set(self.fields or ()) - set(fields_of(self.type) if self.fields else ())
        if unknown:
            raise ValueError(f"fields: {self.type} has no {', '.join(sorted(unknown))}")
        for i, (low, high) in enumerate(self.bounds or ()):
            if not low <= high:
                raise ValueError(f"bounds[{i}]: min {low} is above max {high}")
        return self

    def size(self) -> int | None:
        """The action values the target takes, where its settings say."""
        names = self.joints or self.fields
        return len(names) if names is not None else len(self.bounds) if self.bounds else None


def message(config: ActionTargetConfig, action: np.ndarray) -> dict[str, Any]:
    """The nested fields of the message that carries `action` (its type's entry writes it)."""
    value = Action([float(v) for v in action], config.joints or config.fields,
                   config.time_from_start_ms / 1000)
    return codec.message_fields(config.type, value)


class ActionTarget:
    """Sends one action a tick within the target's policy; the safe action when one is
    refused, and from the deadman."""

    def __init__(self, config: ActionTargetConfig, publish: Publish,
                 safe_action: np.ndarray) -> None:
        self.config = config
        self.safe_action = safe_action
        self.clamped = 0              # actions with a value clamped into its bounds
        self.refused = 0              # actions replaced by the safe action
        self.rate_limited = 0         # actions not sent: too soon after the last
        self._publish = publish
        self._lock = threading.Lock()
        self._last_sent = -np.inf
        self._interval = 1.0 / config.max_rate_hz
        bounds = np.asarray(config.bounds or [], np.float64).reshape(-1, 2)
        self._low, self._high = bounds[:, 0], bounds[:, 1]
        self._deadman = Deadman(self._expire) if config.deadman_ms is not None else None
        self._deadman_s = (config.deadman_ms or 0) / 1000

    def send(self, action: np.ndarray) -> np.ndarray | None:
        """What was sent (the action checked, or the safe action), or None when the rate
        limit held it back."""
        checked = self._checked(action)
        with self._lock:
            now = time.monotonic()
            if now - self._last_sent < self._interval * 0.999:
                self.rate_limited += 1
                return None
            self._publish(message(self.config, checked))
            self._last_sent = now
            if self._deadman is not None:
                self._deadman.renew(self.config.topic, self._deadman_s)
        return checked

    def _checked(self, action: np.ndarray) -> np.ndarray:
        if action.shape != self.safe_action.shape or not np.isfinite(action).all():
            self.refused += 1
            return self.safe_action
        if self._low.size == 0:
            return action
        inside = (action >= self._low) & (action <= self._high)
        if inside.all():
            return action
        if self.config.beyond_bounds == "refuse":
            self.refused += 1
            return self.safe_action
        self.clamped += 1
        return np.clip(action, self._low, self._high)

    def _expire(self, topic: str) -> None:
        with self._lock:
            self._publish(message(self.config, self.safe_action))
        log.warning("control target %s: no action for %d ms, the safe action sent", topic,
                    self.config.deadman_ms)

    def close(self) -> None:
        """The safe action, last."""
        if self._deadman is not None:
            self._deadman.close()
        with self._lock:
            self._publish(message(self.config, self.safe_action))
