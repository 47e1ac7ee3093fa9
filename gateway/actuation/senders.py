"""Where an allowed command goes: a ROS topic (through the sender the caller makes:
oricf.gateway.ros.commands, so that rclpy stays in ros/) or a text channel of the pipeline
(a line to every client)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, Protocol

from oricf.errors import ConfigError
from oricf.gateway.actuation.policy import AgentPolicy
from oricf.gateway.channels.server import Channels

log = logging.getLogger(__name__)


class Sender(Protocol):
    def send(self, target: str, fields: dict[str, Any]) -> None: ...

    def close(self) -> None: ...


# policy -> the sender of its topic targets (oricf.gateway.ros.commands.RosSender, made by
# the shells so that nothing here imports ROS).
MakeSender = Callable[[AgentPolicy], Sender]


class ChannelSender:
    def __init__(self, policy: AgentPolicy, channels: Channels) -> None:
        self._channels = {name: channels.get(t.channel) for name, t in policy.targets.items()
                          if t.channel}

    def send(self, target: str, fields: dict[str, Any]) -> None:
        self._channels[target].send(str(fields["data"]))

    def close(self) -> None:
        pass


class Senders:
    """Every target's sender: `ros_sender(policy)` is made only where a target is a topic
    (rclpy imported then)."""

    def __init__(self, policy: AgentPolicy, channels: Channels,
                 ros_sender: MakeSender | None = None) -> None:
        self._topics = {name for name, t in policy.targets.items() if t.topic}
        if self._topics and ros_sender is None:
            raise ConfigError(f"agent targets on ROS topics ({', '.join(sorted(self._topics))})"
                              f" need a ROS sender here")
        self.ros = ros_sender(policy) if self._topics and ros_sender is not None else None
        self.text = ChannelSender(policy, channels)

    def send(self, target: str, fields: dict[str, Any]) -> None:
        if target in self._topics:
            assert self.ros is not None
            self.ros.send(target, fields)
        else:
            self.text.send(target, fields)

    def close(self) -> None:
        if self.ros is not None:
            self.ros.close()
