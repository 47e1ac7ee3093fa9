"""The ROS 2 node: input topics -> Pipeline routes -> output topics.

A thread per route, so a slow language-model call never delays the camera route. Camera
inputs have a receive thread of their own (oricf.gateway.ros.camera) that also runs the
route, at depth 1 (newest frame only), best effort like sensor_data until the topic's
publishers are found, then reliable if every one of them is (camera drivers we did not
write); text and audio inputs run on the executor, one callback group per route, reliable,
queued up to the route's queue_size, and are handed to the route's worker thread. A
placement's `battery_topic` (sensor_msgs/BatteryState) is read on the executor, newest
message only, best effort so that reliable and best-effort publishers both match. Outputs
go through the pipeline's outlets; topic outputs to this node's publishers
(oricf.gateway.ros.publishers).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import serialize_message

from oricf.gateway.config import InputConfig, PipelineConfig
from oricf.gateway.endpoints.placement import Placement
from oricf.gateway.inputs import pipeline_sources
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.recorder import Recorder, message_times
from oricf.gateway.ros import messages
from oricf.gateway.ros.camera import CameraReceiver
from oricf.gateway.ros.publishers import TopicPublishers
from oricf.gateway.topics.types import IMAGE_INPUTS

log = logging.getLogger(__name__)


def input_qos(config: InputConfig) -> QoSProfile:
    if config.type in IMAGE_INPUTS:
        qos = QoSProfile(depth=1)
        qos.reliability = qos_profile_sensor_data.reliability
        qos.durability = qos_profile_sensor_data.durability
        qos.history = qos_profile_sensor_data.history
        return qos
    return QoSProfile(depth=config.queue_size, reliability=ReliabilityPolicy.RELIABLE)


def battery_reader(placement: Placement) -> Callable[[Any], None]:
    """A BatteryState callback that gives the charge to the placement."""
    return lambda msg: placement.battery_read(float(msg.percentage))


class GatewayNode(Node):
    def __init__(self, config: PipelineConfig, context: Context | None = None,
                 recorder: Recorder | None = None) -> None:
        super().__init__(config.node_name, context=context)
        self._recorder = recorder  # --record: every topic input and output into a file
        self._cameras: list[CameraReceiver] = []
        self._outlets = Outlets(config, TopicPublishers(self, config, recorder))
        self.pipeline = Pipeline(config, self._outlets)
        self._sources = pipeline_sources(self.pipeline, self._outlets.channels,
                                         lambda route: None)
        for name, route in config.routes.items():
            if route.input.topic is not None:
                self._subscribe(name, route.input)
        self._subscribe_batteries()
        if config.stats_interval_s > 0:
            self.create_timer(config.stats_interval_s, self.pipeline.log_stats)
        # Every ROS entity exists before any thread starts: a SIGTERM during start-up makes
        # creating one fail (the context is shut down), and then nothing is left running.
        self.pipeline.start(inline=[camera.route for camera in self._cameras])
        for camera in self._cameras:
            camera.start()
        self._outlets.start()
        for source in self._sources:
            source.start()
        log.info("gateway node %s: %d routes", config.node_name, len(config.routes))

    def _subscribe(self, route: str, config: InputConfig) -> None:
        assert config.topic is not None and config.type is not None
        if config.type in IMAGE_INPUTS:
            self._cameras.append(CameraReceiver(self, route, config, input_qos(config),
                                                self.pipeline.handle_here, self._recorder))
        else:
            self._subscribe_queued(route, config)
        log.info("route %s: %s (%s) -> %s", route, config.topic, config.type,
                 self.pipeline.config.routes[route].call.method)

    def _subscribe_queued(self, route: str, config: InputConfig) -> None:
        """Text, numbers, audio: on the executor, handed to the route's worker thread."""
        recorder, name = self._recorder, self.resolve_topic_name(str(config.topic))
        submit = self.pipeline.submit

        def on_message(msg: Any, info: dict[str, Any]) -> None:
            load = messages.loader(config, msg)
            if recorder is not None:
                load = recorder.input(name, str(config.type), serialize_message(msg),
                                      *message_times(info), load)
            submit(route, load)

        # rclpy passes the message info to a callback with two parameters; its type
        # hint only names the one-parameter form.
        self.create_subscription(messages.message_type(str(config.type)), config.topic,
                                 on_message,  # type: ignore[arg-type]
                                 input_qos(config),
                                 callback_group=MutuallyExclusiveCallbackGroup())

    def _subscribe_batteries(self) -> None:
        """Each placement's battery topic, into its placement."""
        from sensor_msgs.msg import BatteryState

        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        for name, endpoint in self.pipeline.endpoints.items():
            placement = endpoint.placement
            if placement is None or placement.config.battery_topic is None:
                continue
            topic = placement.config.battery_topic
            self.create_subscription(BatteryState, topic, battery_reader(placement), qos)
            log.info("endpoint %s: battery from %s", name, topic)

    @property
    def outlets(self) -> Outlets:
        """Where outputs go, text channels included (the agent's targets use them too)."""
        return self._outlets

    def shutdown(self) -> None:
        for source in self._sources:
            source.stop()
        for camera in self._cameras:
            camera.stop()
        self.pipeline.stop()
        self._outlets.close()
