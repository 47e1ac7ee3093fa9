"""A control input's settings: `input: {control: ...}` of a route (docs/control.md).

    routes:
      arm:
        input:
          control:
            rate_hz: 80
            state: [{topic: /arm/joint_states, type: sensor_msgs/JointState,
                     fields: [position, velocity]}]
            images: [{name: wrist, topic: /arm/wrist/image_raw}]   # the policy's cameras
            max_age_ms: 50          # an older state part: nothing is asked
            action_dim: 4
            safe_action: [0, 0, 0, 0]
            request_at: 6           # ask when this many actions are left queued
            deadline_steps: 12      # ask again when an answer is this late
            max_ahead_ms: 500       # the policy's horizon: no action planned further ahead
            late: skip              # or shift (oricf.gateway.control.queue)
            merge: ensemble         # or {mode: ensemble, k: 0.02} (oricf.gateway.control.merge)
            target: {topic: /arm/command, type: std_msgs/Float64MultiArray,
                     bounds: [[-1, 1], [-1, 1], [-1, 1], [-1, 1]], deadman_ms: 100}
        call: {method: Act, service: arm_policy}
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.gateway.control.merge import Latest, Merge
from oricf.gateway.control.parts import CameraPart, StatePart
from oricf.gateway.control.queue import MAX_AHEAD, Late
from oricf.gateway.control.target import ActionTargetConfig


class ControlSettings(Schema):
    rate_hz: float = Field(gt=0, le=1000, description="ticks a second (the policy's rate)")
    tick: Literal["clock", "state"] = Field(
        "clock", description="clock: the loop ticks on its own clock at rate_hz; state: each "
        "message of the first state part is a step (the robot's own clock), and its action "
        "goes out as soon as it is known: at once when queued, else when the answer to that "
        "state comes (or with the next state)")
    state: list[StatePart] = Field(min_length=1, max_length=32)
    images: list[CameraPart] = Field(
        default_factory=list, max_length=8,
        description="the policy's cameras: the newest image of each goes with the state")
    max_age_ms: float = Field(100.0, gt=0, le=10_000)
    action_dim: int = Field(ge=1, le=4096)
    safe_action: list[float] | None = Field(None, description="sent when nothing is "
                                            "queued (default: zeros)")
    hold_steps: int = Field(0, ge=0, le=10_000, description="ticks the last action is "
                            "repeated before the safe action")
    request_at: int = Field(0, ge=0, le=10_000)
    deadline_steps: int = Field(10, ge=1, le=100_000)
    max_in_flight: int = Field(1, ge=1, le=64)
    max_ahead_ms: float | None = Field(
        None, gt=0, le=600_000, description="the policy's horizon: an action for a step "
        "further than this after the observation it answers is dropped, and a chunk that "
        "starts there refused (default: one second, or one step where a step is longer)")
    late: Late = "skip"
    merge: Merge = Field(default_factory=Latest, description="how the actions two chunks "
                         "give for one step are merged: a mode of MERGES by its name, or "
                         "{mode: NAME, its keys}")
    send_committed: bool = False
    target: ActionTargetConfig

    @model_validator(mode="after")
    def _consistent(self) -> ControlSettings:
        if self.safe_action is not None and len(self.safe_action) != self.action_dim:
            raise ValueError(f"safe_action: {len(self.safe_action)} values for action_dim "
                             f"{self.action_dim}")
        names = [camera.name for camera in self.images]
        if len(set(names)) != len(names):
            raise ValueError(f"images: a camera is named twice ({', '.join(names)})")
        if not 1 <= self.ahead_steps() <= MAX_AHEAD:
            raise ValueError(f"max_ahead_ms: {self.max_ahead_ms:g} ms is "
                             f"{self.ahead_steps()} steps at {self.rate_hz:g} Hz: from one "
                             f"step to {MAX_AHEAD}")
        size = self.target.size()
        if size is not None and size != self.action_dim:
            raise ValueError(f"target: its joints, fields or bounds give {size} values for "
                             f"action_dim {self.action_dim}")
        return self

    def safe(self) -> np.ndarray:
        return np.asarray(self.safe_action or [0.0] * self.action_dim, np.float64)

    def ahead_steps(self) -> int:
        """The policy's horizon in whole steps at `rate_hz` (the queue's `horizon`): by
        default one second, or one step where a step is longer."""
        if self.max_ahead_ms is None:
            return max(1, math.floor(self.rate_hz + 1e-6))
        # The tolerance keeps 1000 ms at 60.606 Hz 60 steps, not 59.
        return math.floor(self.max_ahead_ms * self.rate_hz / 1000 + 1e-6)

    def state_size(self) -> int:
        """The state's length as the parts say, or -1 when a part does not say (checked on
        the first observation against what arrives)."""
        sizes = [part.expected() for part in self.state]
        return -1 if None in sizes else sum(size or 0 for size in sizes)
