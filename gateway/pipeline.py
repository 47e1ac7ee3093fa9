"""A whole pipeline without ROS: endpoints, data products, routes and their workers.

The ROS node (oricf.gateway.shells.ros_node) only subscribes to input topics, submits loaders here,
and publishes what the emitter receives (oricf.gateway.components.Emitter: the pipeline's
outlets). Tests and benchmarks drive this class directly too, with emitters of their own.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Mapping
from typing import Any

from oricf.gateway.components import METHODS, Emitter
from oricf.gateway.config import PipelineConfig
from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.metrics import pipeline_registry
from oricf.gateway.products import ProductStore
from oricf.gateway.route import Loader, Route, with_trace_context
from oricf.gateway.speaking import Speaking
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.worker import RouteWorker
from oricf.metrics import MetricsServer

log = logging.getLogger(__name__)

ERROR_LOG_INTERVAL_S = 10.0


class Pipeline:
    def __init__(self, config: PipelineConfig, emitter: Emitter,
                 products: ProductStore | None = None, speaking: Speaking | None = None
                 ) -> None:
        self.config = config
        self.products = products or ProductStore()
        # Outlets that play speech hold the speaking state; routes that mute or barge in
        # must see that one, so it is taken from them unless given.
        self.speaking = speaking or emitter.speaking or Speaking()
        # The speakers those outlets play on, for /metrics (device -> Speaker).
        self.speakers: Mapping[str, Any] = emitter.speakers
        throttle = ThrottledLog(logging.getLogger("oricf.gateway.route"), ERROR_LOG_INTERVAL_S)
        used = {route.call.service for route in config.routes.values()}
        self.endpoints = {name: Endpoint(name, cfg, METHODS[config.method_of(name)],
                                         config.step_of(name), config.reply_bytes_of(name))
                          for name, cfg in config.endpoints.items() if name in used}
        for route_config in config.routes.values():
            for output in route_config.outputs:
                if output.product is not None:
                    self.products.declare(output.product, output.max_age_s)
        self.metrics_server: MetricsServer | None = None
        # Control inputs' loops by route (oricf.gateway.control), for /metrics.
        self.loops: dict[str, ControlLoop] = {}
        self.routes: dict[str, Route] = {}
        self.workers: dict[str, RouteWorker[Loader]] = {}
        for name, rc in config.routes.items():
            route = Route(name, rc, self.endpoints[rc.call.service], self.products, emitter,
                          throttle, self.speaking)
            self.routes[name] = route
            self.workers[name] = RouteWorker(name, route, rc.input.mode,
                                             rc.input.queue_size)
            if rc.input.product is not None:
                self.products.subscribe(rc.input.product, self._feeder(name))
        self.speaking.on_interrupt(self._drop_pending_speech)

    def _drop_pending_speech(self) -> None:
        """Barge-in: sentences waiting to be synthesized are dropped."""
        for name, rc in self.config.routes.items():
            if METHODS[rc.call.method].speaks:
                self.workers[name].clear()

    def _feeder(self, route: str) -> Callable[[Any], None]:
        def feed(value: Any) -> None:
            self.submit(route, lambda: {"value": value})

        return feed

    def submit(self, route: str, load: Loader) -> None:
        self.workers[route].submit(with_trace_context(load))

    def handle_here(self, route: str, load: Loader, missed: int = 0) -> None:
        """Runs one item in the caller's thread (a route started `inline`)."""
        self.workers[route].handle_here(with_trace_context(load), missed)

    def start(self, inline: Collection[str] = ()) -> None:
        """Starts the worker threads, except those of `inline` routes: the caller feeds
        those through handle_here from threads of its own."""
        if self.config.metrics is not None:  # first: an address in use stops the start
            self.metrics_server = MetricsServer(self.config.metrics, pipeline_registry(self))
        for name, worker in self.workers.items():
            if name not in inline:
                worker.start()
        for name, endpoint in self.endpoints.items():
            fallback = f", fallback {endpoint.fallback.address}" if endpoint.fallback else ""
            images = (f", images {endpoint.config.image.transport}"
                      if METHODS[self.config.method_of(name)].image_transport else "")
            log.info("endpoint %s: %s%s, deadline %d ms%s", name, endpoint.primary.address,
                     fallback, endpoint.config.deadline_ms, images)

    def idle(self, timeout: float) -> bool:
        return all(worker.idle(timeout) for worker in self.workers.values())

    def log_stats(self) -> None:
        for name, route in self.routes.items():
            stats = self.workers[name].stats
            log.info("route %s: %d received, %d dropped as stale, %d ok, %d skipped, "
                     "errors %s", name, stats.received, stats.dropped, route.stats.ok,
                     route.stats.skipped, route.stats.errors or "none")

    def stop(self) -> None:
        for worker in self.workers.values():
            worker.stop()
        for route in self.routes.values():  # before the endpoints their methods call
            route.close()
        for endpoint in self.endpoints.values():
            endpoint.close()
        self.log_stats()
        if self.metrics_server is not None:
            self.metrics_server.close()
