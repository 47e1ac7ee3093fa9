"""One pipeline's parts and their lifecycle, the same under every shell.

    configure   build: the outlets (their sinks open, so a speaker that is not there fails
                here), the pipeline (endpoints, data products, routes and their workers) and
                the sources; nothing runs yet
    activate    start: text channels bound, /metrics, the route workers, the live view, the
                inputs, then the operations and the control API
    deactivate  stop taking work: the control API and the agent's actuation first (its
                deadman's zero goes out while ROS still runs), the inputs, the routes drain
                (up to `drain_s`), then the live view and the route workers
    cleanup     close: the sinks and the text channels

The steps are a ROS 2 lifecycle node's (configure, activate, deactivate, cleanup), each taken
once: a deactivated gateway has closed its endpoints and is not activated again. The shells
(oricf.gateway.shells) add only what is theirs: a ROS node's subscriptions and publishers,
a replayed recording, the MCP server.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.senders import MakeSender
from oricf.gateway.components import Emitter, OnEnd, Source, TopicIo
from oricf.gateway.config import PipelineConfig
from oricf.gateway.host.surfaces import make_view, serve_control, start_live_view
from oricf.gateway.inputs import pipeline_sources
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.tracing import setup_tracing

if TYPE_CHECKING:
    from oricf.gateway.live_view.view import LiveView  # foxglove-sdk, only when used

log = logging.getLogger(__name__)


Stop = Callable[[], None]


def stopped(stop: Stop | None) -> None:
    """Runs a stop, if there is one, logging what it raises (the next stop still runs)."""
    if stop is None:
        return
    try:
        stop()
    except Exception:
        log.exception("stopping the gateway")


def no_end(route: str) -> None:
    """Sources that end are not waited for (the ROS node, the MCP server)."""


class LifecycleError(RuntimeError):
    """A step taken out of order (activate before configure...)."""


class Gateway:
    """configure() -> activate() -> deactivate() -> cleanup(); `view` is the operations on
    the running pipeline (the control API's and MCP's), made on activate when asked for."""

    def __init__(self, config: PipelineConfig, ros_sender: MakeSender | None = None,
                 audit_path: Path | None = None) -> None:
        self.config = config
        self._ros_sender = ros_sender     # the agent's topic targets (rclpy: the shell's)
        self._audit_path = audit_path or (config.agent.audit if config.agent else None)
        self._outlets: Outlets | None = None
        self._pipeline: Pipeline | None = None
        self.inputs: list[Source] = []
        self.view: PipelineView | None = None
        # What activate started, each stopped once by deactivate.
        self._running: list[Source] = []
        self._control: Stop | None = None      # the control API and the view
        self.live_view: LiveView | None = None
        self._workers: Stop | None = None      # the routes' workers, endpoints, /metrics

    @property
    def pipeline(self) -> Pipeline:
        if self._pipeline is None:
            raise LifecycleError("the gateway is not configured")
        return self._pipeline

    @property
    def outlets(self) -> Outlets:
        if self._outlets is None:
            raise LifecycleError("the gateway is not configured")
        return self._outlets

    def configure(self, ros: Emitter | None = None, on_end: OnEnd = no_end,
                  topics: TopicIo | None = None) -> None:
        """Builds every part; `ros` takes topic outputs, `on_end` hears of ended sources,
        `topics` are the ROS node's for sources that use their own (a control loop)."""
        setup_tracing("oricf-gateway", self.config.tracing)  # once per process
        self._outlets = Outlets(self.config, ros)
        try:
            self._pipeline = Pipeline(self.config, self._outlets)
            self.inputs = pipeline_sources(self._pipeline, self._outlets.channels, on_end,
                                           topics)
        except BaseException:
            self.cleanup()
            raise

    def add_inputs(self, inputs: Iterable[Source]) -> None:
        """Inputs the shell feeds (ROS cameras, a replay): started and stopped with the
        sources."""
        self.inputs.extend(inputs)

    def activate(self, inline: Collection[str] = (), operations: bool = False) -> None:
        """Starts everything; `inline` routes are run by their inputs' own threads (ROS
        cameras); with `operations`, or a `control:` key, the view is made. A part that
        fails to start stops those started before it."""
        pipeline = self.pipeline
        try:
            self.outlets.start()
            pipeline.start(inline)
            self._workers = pipeline.stop
            if self.config.foxglove is not None:
                self.live_view = start_live_view(pipeline, self.config.foxglove)
            for source in self.inputs:
                source.start()
                self._running.append(source)
            if operations or self.config.control is not None:
                self.view = make_view(pipeline, self.outlets.channels,
                                      AuditLog(self._audit_path), self._ros_sender)
                self._control = serve_control(self.view)
        except BaseException:
            self.deactivate()
            raise

    def deactivate(self, drain_s: float = 0.0) -> None:
        """Stops what activate started: the control API and the actuation, the inputs; the
        routes drain what they hold (up to `drain_s`); the live view, the route workers."""
        stopped(self._control)
        self._control = None
        while self._running:
            source = self._running.pop()
            stopped(source.stop)
        if drain_s > 0 and self._workers is not None:
            self.pipeline.idle(drain_s)
        if self.live_view is not None:
            stopped(self.live_view.stop)
            self.live_view = None
        stopped(self._workers)
        self._workers = None

    def cleanup(self) -> None:
        if self._outlets is not None:
            self._outlets.close()

    def close(self) -> None:
        """deactivate, then cleanup."""
        self.deactivate()
        self.cleanup()
