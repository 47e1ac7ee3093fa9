"""The `agent:` policy of a pipeline YAML: what an agent may send, where, how fast, within
which bounds, and with whose approval. Everything not listed is refused.

    agent:
      audit: agent-audit.jsonl        # every tool call, allowed or refused (JSON lines)
      targets:
        cmd_vel:
          topic: /cmd_vel
          type: geometry_msgs/Twist
          bounds: {linear.x: [-0.3, 0.3], angular.z: [-0.5, 0.5]}   # others stay 0
          beyond_bounds: clamp        # or refuse
          max_rate_hz: 10
          approval: none              # elicit: the agent's user says yes (MCP elicitation)
                                      # channel: a person answers on approval_channel
          deadman_ms: 500             # a zero command when not renewed in time
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from oricf.config import FilePath, Schema
from oricf.errors import OricfError
from oricf.gateway.actuation.messages import check_fields, fields_of, flatten
from oricf.gateway.topics import types

NUMERIC = {"float", "int"}


class Refused(OricfError):
    """The policy refuses a command; the message says why."""


class TargetPolicy(Schema):
    """One place an agent may write to: a ROS topic or a text channel."""

    topic: str | None = Field(None, description="a ROS topic")
    channel: str | None = Field(None, description="a text channel of the pipeline")
    type: str = Field(types.TEXT, description="the message type: an agent command type of "
                      "oricf.gateway.topics.types")
    description: str = Field("", max_length=500, description="what the target does, for "
                                                             "the agent")
    bounds: dict[str, tuple[float, float]] = Field(
        default_factory=dict, description="numeric field -> [min, max]; a numeric field "
                                          "not listed must be 0")
    beyond_bounds: Literal["clamp", "refuse"] = "refuse"
    max_rate_hz: float = Field(5.0, gt=0, le=1000)
    approval: Literal["none", "elicit", "channel"] = "none"
    approval_channel: str | None = None
    approval_timeout_s: float = Field(30.0, gt=0, le=600)
    deadman_ms: int | None = Field(None, ge=10, le=60_000, description="send the zero "
                                   "command this long after the last one unless renewed")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str) -> str:
        return types.check(type_, "command", "an agent command type")

    @model_validator(mode="after")
    def _consistent(self) -> TargetPolicy:
        if (self.topic is None) == (self.channel is None):
            raise ValueError("give exactly one of topic or channel")
        if self.channel is not None and self.type != types.TEXT:
            raise ValueError(f"a channel carries text: type {types.TEXT}")
        fields = fields_of(self.type)
        for name, (low, high) in self.bounds.items():
            if fields.get(name) not in NUMERIC:
                numeric = [f for f, kind in fields.items() if kind in NUMERIC]
                raise ValueError(f"bounds: {self.type} has no numeric field {name!r} "
                                 f"(numeric fields: {', '.join(numeric) or 'none'})")
            if low > high:
                raise ValueError(f"bounds.{name}: min {low} is above max {high}")
        if (self.approval == "channel") != (self.approval_channel is not None):
            raise ValueError("approval: channel goes with approval_channel, and only with it")
        if self.deadman_ms is not None and not set(fields.values()) <= NUMERIC:
            raise ValueError(f"deadman_ms: {self.type} has no zero command")
        return self

    @property
    def where(self) -> str:
        return f"topic {self.topic}" if self.topic else f"channel {self.channel}"

    def check(self, name: str, message: Any) -> Checked:
        """The message as it would be sent (clamped where the policy says so), or Refused."""
        try:
            flat = check_fields(self.type, flatten(message))
        except OricfError as exc:
            raise Refused(f"{name}: {exc}") from None
        clamped: list[str] = []
        for field, kind in fields_of(self.type).items():
            if kind not in NUMERIC:
                continue
            low, high = self.bounds.get(field, (0.0, 0.0))
            value = flat[field]
            if low <= value <= high:
                continue
            if field not in self.bounds:
                raise Refused(f"{name}: {field} must be 0 (the policy allows no other value)")
            if self.beyond_bounds == "refuse":
                raise Refused(f"{name}: {field}={value} is outside [{low}, {high}]")
            flat[field] = type(value)(min(max(value, low), high))
            clamped.append(f"{field} {value} -> {flat[field]}")
        return Checked(name, flat, clamped)

    def summary(self) -> dict[str, Any]:
        """What an agent is told about the target."""
        return {"where": self.where, "type": self.type, "description": self.description,
                "bounds": {k: list(v) for k, v in self.bounds.items()},
                "beyond_bounds": self.beyond_bounds, "max_rate_hz": self.max_rate_hz,
                "approval": self.approval, "approval_timeout_s": self.approval_timeout_s,
                "deadman_ms": self.deadman_ms}


@dataclass(frozen=True)
class Checked:
    """A command that passed the policy's checks on its content."""

    target: str
    fields: dict[str, Any]
    clamped: list[str]


class AgentPolicy(Schema):
    audit: FilePath | None = Field(None, description="JSON lines of every tool call")
    targets: dict[str, TargetPolicy] = Field(default_factory=dict)

    def target(self, name: str) -> TargetPolicy:
        if name not in self.targets:
            allowed = ", ".join(self.targets) or "none: this pipeline allows no actuation"
            raise Refused(f"{name[:100]!r} is not a target of the agent policy "
                          f"(targets: {allowed})")
        return self.targets[name]
