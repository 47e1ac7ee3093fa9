"""The gateway node's topics for components that read and write their own (a control
loop's state and actions, oricf.gateway.components.TopicIo): subscriptions keep the newest
message only and match reliable and best-effort publishers alike; publishers are reliable
(matched by either kind of subscriber), lifecycle publishers (they publish while the node is
active), and build each message from nested fields."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile, ReliabilityPolicy

from oricf.gateway.ros import messages


def fill(msg: Any, fields: Mapping[str, Any]) -> Any:
    """Sets `fields` on `msg`: a mapping fills a message field, a list of mappings a
    sequence of messages (of the type the field declares)."""
    types = msg.get_fields_and_field_types()
    for name, value in fields.items():
        if isinstance(value, Mapping):
            fill(getattr(msg, name), value)
        elif isinstance(value, list) and value and isinstance(value[0], Mapping):
            element = messages.message_type(types[name].removeprefix("sequence<")
                                            .removesuffix(">"))
            setattr(msg, name, [fill(element(), item) for item in value])
        else:
            setattr(msg, name, value)
    return msg


class NodeTopics:
    def __init__(self, node: LifecycleNode) -> None:
        self._node = node

    def subscribe(self, topic: str, type_: str, take: Callable[[Any], None]) -> None:
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self._node.create_subscription(messages.message_type(type_), topic, take, qos,
                                       callback_group=MutuallyExclusiveCallbackGroup())

    def publisher(self, topic: str, type_: str) -> Callable[[dict[str, Any]], None]:
        message = messages.message_type(type_)
        publisher = self._node.create_lifecycle_publisher(message, topic, QoSProfile(depth=10))
        context = self._node.context

        def publish(fields: dict[str, Any]) -> None:
            if context.ok():  # the context shuts down before the loop's last safe action
                publisher.publish(fill(message(), fields))

        return publish
