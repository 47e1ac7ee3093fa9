"""The ROS 2 node: input topics -> Pipeline routes -> output topics.

A thread per route, so a slow language-model call never delays the camera route. Camera
inputs have a receive thread of their own (oricf.gateway.camera) that also runs the route,
at depth 1 (newest frame only), best effort like sensor_data until the topic's publishers
are found, then reliable if every one of them is (camera drivers we did not write); text and
audio inputs run on the executor, one callback group per route, reliable, queued up to the
route's queue_size, and are handed to the route's worker thread.
"""

from __future__ import annotations

import logging
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import serialize_message

from oricf.gateway import convert
from oricf.gateway.camera import CameraReceiver
from oricf.gateway.config import IMAGE_INPUTS, InputConfig, OutputConfig, PipelineConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.record import Recorder, message_times
from oricf.gateway.sinks import Outlets
from oricf.gateway.standalone import pipeline_sources
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Record

log = logging.getLogger(__name__)


def input_qos(config: InputConfig) -> QoSProfile:
    if config.type in IMAGE_INPUTS:
        qos = QoSProfile(depth=1)
        qos.reliability = qos_profile_sensor_data.reliability
        qos.durability = qos_profile_sensor_data.durability
        qos.history = qos_profile_sensor_data.history
        return qos
    return QoSProfile(depth=config.queue_size, reliability=ReliabilityPolicy.RELIABLE)


class GatewayNode(Node):
    def __init__(self, config: PipelineConfig, context: Context | None = None,
                 recorder: Recorder | None = None) -> None:
        super().__init__(config.node_name, context=context)
        self._publishers_by_topic: dict[str, Publisher] = {}
        self._recorder = recorder  # --record: every topic input and output into a file
        self._topic_names: dict[str, str] = {}  # output topic -> its full ROS name
        self._throttle = ThrottledLog(log)
        self._cameras: list[CameraReceiver] = []
        self._outlets = Outlets(config)  # outputs that are not topics (JSON lines, files)
        self.pipeline = Pipeline(config, self._emit)
        self._sources = pipeline_sources(self.pipeline, self._outlets, lambda route: None)
        for route in config.routes.values():
            for output in route.outputs:
                if output.topic is not None:
                    self._publisher(output)
        for name, route in config.routes.items():
            if route.input.topic is not None:
                self._subscribe(name, route.input)
        self.pipeline.start(inline=[camera.route for camera in self._cameras])
        for camera in self._cameras:
            camera.start()
        self._outlets.start()
        for source in self._sources:
            source.start()
        if config.stats_interval_s > 0:
            self.create_timer(config.stats_interval_s, self.pipeline.log_stats)
        log.info("gateway node %s: %d routes", config.node_name, len(config.routes))

    def _publisher(self, output: OutputConfig) -> Publisher:
        assert output.topic is not None and output.type is not None
        publisher = self._publishers_by_topic.get(output.topic)
        if publisher is None:
            # Reliable publishers match both reliable and best-effort subscribers.
            depth = 1 if output.type == "sensor_msgs/Image" else 10
            publisher = self.create_publisher(convert.MESSAGE_TYPES[output.type], output.topic,
                                              depth)
            self._publishers_by_topic[output.topic] = publisher
            self._topic_names[output.topic] = publisher.topic_name
        return publisher

    def _subscribe(self, route: str, config: InputConfig) -> None:
        assert config.topic is not None and config.type is not None
        msg_type = convert.MESSAGE_TYPES[config.type]
        recorder, name = self._recorder, self.resolve_topic_name(config.topic)
        if config.type in IMAGE_INPUTS:
            type_, handle_here = config.type, self.pipeline.handle_here

            def on_frame(serialized: bytes, missed: int, info: dict[str, Any]) -> None:
                load = convert.image_loader(type_, serialized)
                if recorder is not None:
                    load = recorder.input(name, type_, serialized, *message_times(info), load)
                handle_here(route, load, missed)

            self._cameras.append(CameraReceiver(self, route, msg_type, config.topic,
                                                input_qos(config), on_frame))
        else:
            submit = self.pipeline.submit

            def on_message(msg: Any, info: dict[str, Any]) -> None:
                load = convert.loader(config, msg)
                if recorder is not None:
                    load = recorder.input(name, str(config.type), serialize_message(msg),
                                          *message_times(info), load)
                submit(route, load)

            # rclpy passes the message info to a callback with two parameters; its type
            # hint only names the one-parameter form.
            self.create_subscription(msg_type, config.topic, on_message,  # type: ignore[arg-type]
                                     input_qos(config),
                                     callback_group=MutuallyExclusiveCallbackGroup())
        log.info("route %s: %s (%s) -> %s", route, config.topic, config.type,
                 self.pipeline.config.routes[route].call.method)

    def _emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        if output.topic is None:
            self._outlets(output, value, record)
            return
        assert output.type is not None
        try:
            msg = convert.to_message(output.type, value, record.get("header"))
        except (TypeError, ValueError) as exc:  # a value that does not fit the topic type
            self._throttle.error(f"emit:{output.topic}", "cannot publish %r on %s (%s): %s",
                                 value, output.topic, output.type, exc)
            return
        try:
            self._publishers_by_topic[output.topic].publish(msg)
        except Exception:
            # SIGTERM shuts the ROS context down before the camera threads stop, so a frame
            # in flight may finish after it: nothing can be published any more, and that
            # is not an error of the route.
            if self.context.ok():
                raise
            log.debug("shutting down: %s not published", output.topic)
        if self._recorder is not None:
            self._recorder.output(self._topic_names[output.topic], output.type, value, record)

    def shutdown(self) -> None:
        for source in self._sources:
            source.stop()
        for camera in self._cameras:
            camera.stop()
        self.pipeline.stop()
        self._outlets.close()
