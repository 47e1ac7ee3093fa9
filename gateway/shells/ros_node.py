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
from pathlib import Path
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import serialize_message

from oricf.gateway.config import InputConfig, PipelineConfig
from oricf.gateway.endpoints.placement import Placement
from oricf.gateway.host.gateway import Gateway
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.recorder import Recorder, message_times
from oricf.gateway.ros import messages
from oricf.gateway.ros.camera import CameraReceiver
from oricf.gateway.ros.commands import RosSender
from oricf.gateway.ros.publishers import TopicPublishers
from oricf.gateway.ros.topic_io import NodeTopics
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
    """The gateway as a ROS 2 node: a Gateway (oricf.gateway.host) whose topic inputs are
    this node's subscriptions and whose topic outputs are its publishers. The constructor
    makes the node alone; configure() makes the gateway's parts, the publishers and the
    subscriptions, activate() starts them, shutdown() stops and closes them."""

    def __init__(self, config: PipelineConfig, context: Context | None = None,
                 recorder: Recorder | None = None, audit_path: Path | None = None) -> None:
        super().__init__(config.node_name, context=context)
        self.config = config
        self._recorder = recorder  # --record: every topic input and output into a file
        self._cameras: list[CameraReceiver] = []
        self.gateway = Gateway(config, RosSender, audit_path)

    def configure(self) -> None:
        """Every ROS entity is made here, before any thread starts: a SIGTERM during
        start-up makes creating one fail (the context is shut down), and then nothing is
        left running."""
        self.gateway.configure(TopicPublishers(self, self.config, self._recorder),
                               topics=NodeTopics(self))
        for name, route in self.config.routes.items():
            if route.input.topic is not None:
                self._subscribe(name, route.input)
        self.gateway.add_inputs(self._cameras)
        self._subscribe_batteries()
        if self.config.stats_interval_s > 0:
            self.create_timer(self.config.stats_interval_s, self.pipeline.log_stats)

    def activate(self, operations: bool = False) -> None:
        """Starts the gateway; camera routes run on their receive threads."""
        self.gateway.activate(inline=[camera.route for camera in self._cameras],
                              operations=operations)
        log.info("gateway node %s: %d routes", self.config.node_name, len(self.config.routes))

    @property
    def pipeline(self) -> Pipeline:
        return self.gateway.pipeline

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
        return self.gateway.outlets

    def shutdown(self) -> None:
        """The control API and the actuation first, then inputs, routes and outputs."""
        self.gateway.deactivate()
        self.gateway.cleanup()
