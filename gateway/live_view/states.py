"""What the live view plots about the pipeline itself, once a second: each endpoint's state
(the address in use, on the fallback or not, failovers, recoveries, retries, the latest
latency of the routes that call it) and each route's counts. Read from the counts the parts
already keep, as the metrics are (oricf.gateway.metrics)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Protocol

from oricf.gateway.config import PipelineConfig
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.route import Route
from oricf.gateway.worker import RouteWorker


class Pipeline(Protocol):
    """The parts of a pipeline whose state is shown (oricf.gateway.pipeline.Pipeline)."""

    config: PipelineConfig
    routes: Mapping[str, Route]
    workers: Mapping[str, RouteWorker[Any]]
    endpoints: Mapping[str, Endpoint]


def endpoint_state(name: str, endpoint: Endpoint, routes: list[Route]) -> dict[str, Any]:
    active = endpoint.active
    return {"active": active.address,
            "on_fallback": endpoint.fallback is not None and active is endpoint.fallback,
            "failovers": endpoint.failovers, "recoveries": endpoint.recoveries,
            "retries": endpoint.retries,
            "latency_ms": max((r.stats.last_ms for r in routes), default=0.0)}


def route_state(route: Route, worker: RouteWorker[Any]) -> dict[str, Any]:
    return {"received": worker.stats.received, "dropped": worker.stats.dropped,
            "ok": route.stats.ok, "skipped": route.stats.skipped,
            "errors": sum(route.stats.errors.values()), "latency_ms": route.stats.last_ms}


def states(pipeline: Pipeline) -> Iterator[tuple[str, dict[str, Any]]]:
    """(topic, state) for every endpoint and route."""
    for name, endpoint in pipeline.endpoints.items():
        callers = [r for r in pipeline.routes.values() if r.config.call.service == name]
        yield f"/endpoints/{name}", endpoint_state(name, endpoint, callers)
    for name, route in pipeline.routes.items():
        yield f"/routes/{name}/state", route_state(route, pipeline.workers[name])
