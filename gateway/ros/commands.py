"""An agent's commands on ROS topics: a node of its own, `oricf_agent`, in a private rclpy
context, so it works beside the gateway's node or without one. The actuation policy
(oricf.gateway.actuation) decides what is sent; this only publishes it."""

from __future__ import annotations

import logging
import threading
from typing import Any

from oricf.errors import ConfigError
from oricf.gateway.actuation.messages import nested
from oricf.gateway.actuation.policy import AgentPolicy
from oricf.gateway.ros.dds import use_dds_profile
from oricf.gateway.ros.messages import filled, message_type

log = logging.getLogger(__name__)


class RosSender:
    """One publisher per topic target, made when the sender starts."""

    def __init__(self, policy: AgentPolicy, node_name: str = "oricf_agent") -> None:
        try:
            import rclpy
            from rclpy.context import Context
            from rclpy.node import Node
            from rclpy.qos import QoSProfile
        except ImportError as exc:
            raise ConfigError(f"agent targets on ROS topics need ROS 2's Python packages "
                              f"({exc}): source /opt/ros/jazzy/setup.bash, or pip install "
                              f"'oricf[ros]' on x86-64") from None

        use_dds_profile()
        self._context = Context()
        rclpy.init(context=self._context)
        self._node = Node(node_name, context=self._context)
        self._types = {name: message_type(t.type) for name, t in policy.targets.items()
                       if t.topic}
        self._publishers = {
            name: self._node.create_publisher(self._types[name], t.topic,
                                              QoSProfile(depth=10))
            for name, t in policy.targets.items() if t.topic}
        self._lock = threading.Lock()
        log.info("agent targets on ROS topics: %s", ", ".join(
            f"{name} -> {t.topic} ({t.type})" for name, t in policy.targets.items()
            if t.topic) or "none")

    def send(self, target: str, fields: dict[str, Any]) -> None:
        with self._lock:
            self._publishers[target].publish(filled(self._types[target], nested(fields)))

    def subscribers(self, target: str) -> int:
        return int(self._publishers[target].get_subscription_count())

    def close(self) -> None:
        """After the last (zero) commands are acknowledged by the subscribers, or 1 s."""
        import rclpy
        from rclpy.duration import Duration

        with self._lock:
            for publisher in self._publishers.values():
                publisher.wait_for_all_acked(Duration(seconds=1))
        self._node.destroy_node()
        rclpy.try_shutdown(context=self._context)
