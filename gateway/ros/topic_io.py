"""The gateway node's topics for components that read and write their own (a control
loop's state, cameras and actions, oricf.gateway.components.TopicIo): subscriptions keep the
newest message only and match reliable and best-effort publishers alike, and hand on each
message in the form its type is read (oricf.gateway.topics.types: camera frames serialized,
the rest as rclpy's messages); publishers are reliable (matched by either kind of
subscriber), lifecycle publishers (they publish while the node is active), and fill each
message from its fields (oricf.gateway.ros.messages)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile, ReliabilityPolicy

from oricf.gateway.ros import messages
from oricf.gateway.topics.types import ros_type


class NodeTopics:
    def __init__(self, node: LifecycleNode) -> None:
        self._node = node

    def subscribe(self, topic: str, type_: str, take: Callable[[Any], None]) -> None:
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self._node.create_subscription(messages.message_type(type_), topic, take, qos,
                                       callback_group=MutuallyExclusiveCallbackGroup(),
                                       raw=ros_type(type_).parse is not None)

    def publisher(self, topic: str, type_: str) -> Callable[[dict[str, Any]], None]:
        message = messages.message_type(type_)
        publisher = self._node.create_lifecycle_publisher(message, topic, QoSProfile(depth=10))
        context = self._node.context

        def publish(fields: dict[str, Any]) -> None:
            if context.ok():  # the context shuts down before the loop's last safe action
                publisher.publish(messages.filled(message, fields))

        return publish
