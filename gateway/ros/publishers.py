"""Topic outputs, the pipeline's ROS outputs: one lifecycle publisher per output topic (it
publishes while the node is active); each value converted to its message
(oricf.gateway.ros.messages, from its type's fields) and published, and recorded with
--record."""

from __future__ import annotations

import logging
from typing import Any

from rclpy.lifecycle import LifecycleNode
from rclpy.publisher import Publisher

from oricf.errors import InvalidInput
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, PipelineConfig
from oricf.gateway.recording.recorder import Recorder
from oricf.gateway.ros import messages
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.topics.types import ros_type
from oricf.gateway.values import Record

log = logging.getLogger(__name__)


class TopicPublishers(Emitter):
    """Emits each topic output of the pipeline's routes (oricf.gateway.outlets.Outlets hands
    them on)."""

    def __init__(self, node: LifecycleNode, config: PipelineConfig,
                 recorder: Recorder | None = None) -> None:
        self._node = node
        self._recorder = recorder  # --record: every topic output into a file
        self._throttle = ThrottledLog(log)
        self._publishers: dict[str, Publisher] = {}
        for route in config.routes.values():
            for output in route.outputs:
                if output.topic is not None and output.topic not in self._publishers:
                    assert output.type is not None
                    # Reliable publishers match both reliable and best-effort subscribers.
                    self._publishers[output.topic] = node.create_lifecycle_publisher(
                        messages.message_type(output.type), output.topic,
                        ros_type(output.type).depth)

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        assert output.topic is not None and output.type is not None
        try:
            msg = messages.to_message(output.type, value, record.get("header"))
        except (TypeError, ValueError) as exc:  # a value that does not fit the topic type
            self._throttle.error(f"emit:{output.topic}", "cannot publish %r on %s (%s): %s",
                                 value, output.topic, output.type, exc)
            return
        publisher = self._publishers[output.topic]
        try:
            publisher.publish(msg)
        except Exception:
            # SIGTERM shuts the ROS context down before the camera threads stop, so a frame
            # in flight may finish after it: nothing can be published any more, and that
            # is not an error of the route.
            if self._node.context.ok():
                raise
            log.debug("shutting down: %s not published", output.topic)
        if self._recorder is not None:
            try:
                self._recorder.output(publisher.topic_name, output.type, value, record)
            except (TypeError, ValueError, InvalidInput) as exc:  # a value that does not fit
                # the type, or a type without a writer: published all the same, not recorded
                self._throttle.error(f"record:{output.topic}", "cannot record %s (%s): %s",
                                     output.topic, output.type, exc)
