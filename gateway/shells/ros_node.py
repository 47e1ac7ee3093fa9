"""The ROS 2 node: input topics -> Pipeline routes -> output topics.

A managed (lifecycle) node, driven like ros2/demos' lifecycle talker by `ros2 lifecycle
set`, launch's lifecycle events or a lifecycle manager: its transitions run the gateway's
own steps (oricf.gateway.host). configure makes the host's parts, the publishers
(lifecycle publishers: they publish only while the node is active) and the subscriptions;
activate starts them; deactivate stops taking inputs and stops the host (a control loop's
target gets the safe action last, the agent's targets their zero command) and lets its
parts go, since a stopped host is not started again: the next activate builds them anew;
cleanup lets go of what configure made; shutdown does what is left from any state.
`oricf gateway` takes configure and activate itself (oricf.gateway.shells.ros).

A thread per route, so a slow language-model call never delays the camera route. Camera
inputs have a receive thread of their own (oricf.gateway.ros.camera) that also runs the
route, at depth 1 (newest frame only), best effort like sensor_data until the topic's
publishers are found, then reliable if every one of them is (camera drivers we did not
write); text and audio inputs run on the executor, one callback group per route, reliable,
queued up to the route's queue_size, and are handed to the route's worker thread while the
node is active. A placement's `battery_topic` (sensor_msgs/BatteryState) is read on the
executor, newest message only, best effort so that reliable and best-effort publishers both
match. Outputs go through the pipeline's outlets; topic outputs to this node's publishers
(oricf.gateway.ros.publishers).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeAlias

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.lifecycle import (
    LifecycleNode,
    LifecyclePublisher,
    LifecycleState,
    TransitionCallbackReturn,
)
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import serialize_message
from rclpy.subscription import Subscription

from oricf.errors import ConfigError
from oricf.gateway.config import InputConfig, PipelineConfig
from oricf.gateway.endpoints.placement import Placement
from oricf.gateway.host.gateway import Gateway, LifecycleError
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.recorder import Recorder, message_times
from oricf.gateway.ros import messages
from oricf.gateway.ros.camera import CameraReceiver
from oricf.gateway.ros.commands import RosSender
from oricf.gateway.ros.publishers import TopicPublishers
from oricf.gateway.ros.topic_io import NodeTopics
from oricf.gateway.topics import codec
from oricf.gateway.topics.types import ros_type

log = logging.getLogger(__name__)


def input_qos(config: InputConfig) -> QoSProfile:
    if ros_type(str(config.type)).frames:
        qos = QoSProfile(depth=1)
        qos.reliability = qos_profile_sensor_data.reliability
        qos.durability = qos_profile_sensor_data.durability
        qos.history = qos_profile_sensor_data.history
        return qos
    return QoSProfile(depth=config.queue_size, reliability=ReliabilityPolicy.RELIABLE)


def battery_reader(placement: Placement) -> Callable[[Any], None]:
    """A BatteryState callback that gives the charge to the placement."""
    return lambda msg: placement.battery_read(float(msg.percentage))


Transition = TransitionCallbackReturn  # SUCCESS, FAILURE or ERROR
# A Transition: rclpy's enum comes from its C extension, which has no type information.
Result: TypeAlias = Any
# How long a publisher let go of waits for its reliable subscribers to have its last messages.
ACK_WAIT_S = 1.0


class GatewayNode(LifecycleNode):
    """The gateway as a managed ROS 2 node: a Gateway (oricf.gateway.host) whose topic inputs
    are this node's subscriptions and whose topic outputs are its publishers. The
    constructor stores fields; the lifecycle callbacks (on_configure...) run the host's
    steps, and configure(), activate(), deactivate() and shutdown() take the same
    transitions from code, raising what made one fail."""

    def __init__(self, config: PipelineConfig, context: Context | None = None,
                 recorder: Recorder | None = None, audit_path: Path | None = None) -> None:
        super().__init__(config.node_name, context=context)
        self.config = config
        self._recorder = recorder  # --record: every topic input and output into a file
        self._audit_path = audit_path
        self.gateway = Gateway(config, RosSender, audit_path)
        self._cameras: list[CameraReceiver] = []
        self._own = self._entities()  # the node's own (parameters, lifecycle), never released
        self._built = False  # the host configured (and not yet cleaned up), the entities made
        self._active = False     # inputs taken (a queued message before activate is dropped)
        self._operations = False  # the view made on activate even without `control:`
        self.failure: Exception | None = None  # why the last transition failed
        self._from_code = False  # a transition taken by a method: it raises, so no log

    # The lifecycle callbacks, run by the node's lifecycle services or by the methods below.

    def on_configure(self, state: LifecycleState) -> Result:
        return self._step("configure", self._configure)

    def on_activate(self, state: LifecycleState) -> Result:
        if not self._built:  # deactivated: the stopped host's parts are built anew
            result = self._step("configure", self._configure)
            if result != Transition.SUCCESS:
                return result
        super().on_activate(state)  # the publishers first, so the first outputs go out
        result = self._step("activate", self._activate)
        if result != Transition.SUCCESS:
            super().on_deactivate(state)
        return result

    def on_deactivate(self, state: LifecycleState) -> Result:
        result = self._step("deactivate", self._deactivate)
        super().on_deactivate(state)  # after the host's last outputs (the safe action)
        return result

    def on_cleanup(self, state: LifecycleState) -> Result:
        return self._step("cleanup", self._release)

    def on_shutdown(self, state: LifecycleState) -> Result:
        """From any state: stops what runs and lets go of what is made."""
        if self._active:
            self.on_deactivate(state)
        return self._step("shutdown", self._release)

    def on_error(self, state: LifecycleState) -> Result:
        """A callback raised past _step (it catches every Exception): let go of everything,
        back to unconfigured."""
        self._active = False
        return self._step("error", self._release)

    # The same transitions from code (oricf.gateway.shells.ros, embedded, tests).

    def configure(self) -> None:
        """Every ROS entity is made here, before any thread starts: a SIGTERM during
        start-up makes creating one fail (the context is shut down), and then nothing is
        left running."""
        self._take(self.trigger_configure)

    def activate(self, operations: bool = False) -> None:
        """Starts the gateway; camera routes run on their receive threads. `operations`:
        the view (oricf.gateway.operations) is made even without a `control:` key."""
        self._operations = operations
        self._take(self.trigger_activate)

    def deactivate(self) -> None:
        """Stops the gateway if it runs: the control API and the actuation first."""
        if self.state == "active":
            self._take(self.trigger_deactivate, self.on_deactivate)

    def shutdown(self) -> None:
        """Stops and closes everything, from any state: the node is finalized."""
        if self.state != "finalized":
            self._take(self.trigger_shutdown, self.on_shutdown)

    @property
    def state(self) -> str:
        """The lifecycle state's label: unconfigured, inactive, active or finalized."""
        return str(self._state_machine.current_state[1])

    def _take(self, trigger: Callable[[], Result],
              callback: Callable[[LifecycleState], Result] | None = None) -> None:
        self._from_code = True
        try:
            if callback is not None and not self.context.ok():
                # rcl publishes each transition and refuses once the context is shut down:
                # the steps still run, the node going away with its context.
                result = callback(LifecycleState(self.state, 0))
            else:
                result = trigger()
        finally:
            self._from_code = False
        if result != Transition.SUCCESS:
            raise self.failure or LifecycleError(f"{trigger.__name__}: {result}")

    def _step(self, name: str, step: Callable[[], None]) -> Result:
        """Runs a host step; what it raises fails the transition (rclpy would turn it into
        ERROR without a word) and is logged, or raised by the method that asked for it."""
        try:
            step()
        except Exception as exc:
            self.failure = exc
            if not self._from_code:
                log.error("gateway node %s: %s failed: %s", self.get_name(), name, exc,
                          exc_info=not isinstance(exc, ConfigError))
            return Transition.FAILURE
        self.failure = None
        return Transition.SUCCESS

    # The host's steps with this node's ROS entities.

    def _configure(self) -> None:
        """A fresh host configured (a stopped one is not started again), then the node's
        subscriptions to its inputs."""
        self.gateway = Gateway(self.config, RosSender, self._audit_path)
        try:
            # The host closes what it opened when this fails; the publishers stay to release.
            self.gateway.configure(TopicPublishers(self, self.config, self._recorder),
                                   topics=NodeTopics(self))
        except BaseException:
            self._destroy_entities()
            raise
        self._built = True
        try:
            for name, route in self.config.routes.items():
                if route.input.topic is not None:
                    self._subscribe(name, route.input)
            self.gateway.add_inputs(self._cameras)
            self._subscribe_batteries()
            if self.config.stats_interval_s > 0:
                self.create_timer(self.config.stats_interval_s, self.pipeline.log_stats)
        except BaseException:
            self._release()
            raise

    def _activate(self) -> None:
        try:
            self.gateway.activate(inline=[camera.route for camera in self._cameras],
                                  operations=self._operations)
        except BaseException:
            self._release()  # the host stopped what it had started; it is not started again
            raise
        self._active = True
        log.info("gateway node %s: %d routes", self.config.node_name, len(self.config.routes))

    def _deactivate(self) -> None:
        """Inputs refused, then the host stopped (the control API and the actuation first,
        its deadman's zero out while ROS still runs) and its parts let go."""
        self._active = False
        self.gateway.deactivate()
        self._release()

    def _release(self) -> None:
        """The host's cleanup and the ROS entities made for it destroyed; the host stays
        to be read (its pipeline's counts) until the next configure replaces it."""
        if self._built:  # configured and not yet cleaned up: its sinks closed once
            self.gateway.cleanup()
        self._destroy_entities()
        self._cameras = []
        self._built = False

    def _destroy_entities(self) -> None:
        made = self._entities() - self._own
        for entity in made:  # the last messages (a safe action) delivered before they go
            if isinstance(entity, Publisher) and self.context.ok():
                entity.wait_for_all_acked(Duration(seconds=ACK_WAIT_S))
        for entity in made:
            self._destroy(entity)

    def _entities(self) -> set[Any]:
        return {*self.publishers, *self.subscriptions, *self.timers}

    def _destroy(self, entity: Any) -> None:
        if isinstance(entity, LifecyclePublisher):
            self.destroy_lifecycle_publisher(entity)
        elif isinstance(entity, Publisher):
            self.destroy_publisher(entity)
        elif isinstance(entity, Subscription):
            self.destroy_subscription(entity)
        else:
            self.destroy_timer(entity)

    @property
    def pipeline(self) -> Pipeline:
        return self.gateway.pipeline

    def _subscribe(self, route: str, config: InputConfig) -> None:
        assert config.topic is not None and config.type is not None
        if ros_type(str(config.type)).frames:
            self._cameras.append(CameraReceiver(self, route, config, input_qos(config),
                                                self.pipeline, self._recorder))
        else:
            self._subscribe_queued(route, config)
        log.info("route %s: %s (%s) -> %s", route, config.topic, config.type,
                 self.pipeline.config.routes[route].call.method)

    def _subscribe_queued(self, route: str, config: InputConfig) -> None:
        """Text, numbers, audio: on the executor, handed to the route's worker thread."""
        recorder, name = self._recorder, self.resolve_topic_name(str(config.topic))
        submit = self.pipeline.submit

        def on_message(msg: Any, info: dict[str, Any]) -> None:
            if not self._active:  # inactive: nothing taken, nothing answered later
                return
            load = codec.input_loader(str(config.type), msg, config.sample_rate,
                                      config.channels)
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
