"""MCP resources of a gateway, with update notifications: each data product
(`oricf://products/NAME`, JSON) and the latest annotated frame of each camera route
(`oricf://frames/ROUTE`, JPEG).

While a client listens, a poller reads the gateway twice a second (two control calls: the
products with their values, the routes) and announces a resource whose value changed, at
most once a second each: to clients listening on `subscriptions/listen` (the SDK's bus) and
to clients of older protocol versions that sent `resources/subscribe`. With nobody
listening it reads nothing, so an idle agent costs an attached gateway nothing.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any
from urllib.parse import quote

import anyio
import mcp_types as types
from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.resources import FunctionResource
from mcp.server.subscriptions import InMemorySubscriptionBus, ResourceUpdated, ServerEvent

from oricf.gateway.components import METHODS
from oricf.gateway.operations.api import Operations

log = logging.getLogger(__name__)

POLL_S = 0.5
MIN_NOTIFY_INTERVAL_S = 1.0


def product_uri(name: str) -> str:
    """A product's resource; its name escaped, so a '/', '?' or '#' in it stays in it."""
    return f"oricf://products/{quote(name, safe='')}"


def frame_uri(route: str) -> str:
    return f"oricf://frames/{quote(route, safe='')}"


def takes_frames(method: str) -> bool:
    """Whether routes that call `method` take camera frames (and so have a frame resource)."""
    return METHODS[method].image_transport


class ListenedBus(InMemorySubscriptionBus):
    """The SDK's in-process bus, knowing whether anyone listens."""

    def __init__(self) -> None:
        super().__init__()
        self.listeners = 0

    def subscribe(self, listener: Callable[[ServerEvent], None]) -> Callable[[], None]:
        unsubscribe = super().subscribe(listener)
        self.listeners += 1
        done = False

        def once() -> None:
            nonlocal done
            if not done:
                done = True
                self.listeners -= 1
            unsubscribe()

        return once


class ResourceFeed:
    def __init__(self, gateway: Operations) -> None:
        self.gateway = gateway
        self.bus = ListenedBus()
        self._legacy: dict[str, set[Any]] = {}  # uri -> sessions that subscribed
        self._seen: dict[str, Any] = {}
        self._notified: dict[str, float] = {}

    def register(self, app: MCPServer) -> None:
        gateway = self.gateway
        for product in gateway.products():
            name = product["name"]
            app.add_resource(FunctionResource.from_function(
                lambda name=name: gateway.read_product(name), product_uri(name),
                name=f"product {name}", mime_type="application/json",
                description=f"data product {name}: value, age_s, stale, route"))
        for route in self._camera_routes():
            app.add_resource(FunctionResource.from_function(
                lambda route=route: gateway.look(route)[1], frame_uri(route),
                name=f"frame {route}", mime_type="image/jpeg",
                description=f"the newest frame of route {route}, detections drawn"))
        # Clients of protocol versions before 2026-07-28 subscribe per resource. MCPServer
        # serves only subscriptions/listen, so the older request is added on its server.
        lowlevel = app._lowlevel_server
        lowlevel.add_request_handler("resources/subscribe", types.SubscribeRequestParams,
                                     self._subscribe)
        lowlevel.add_request_handler("resources/unsubscribe", types.UnsubscribeRequestParams,
                                     self._unsubscribe)

    def _camera_routes(self) -> list[str]:
        routes = self.gateway.status()["routes"]
        return [name for name, r in routes.items() if takes_frames(r["method"])]

    async def _subscribe(self, ctx: Any, params: types.SubscribeRequestParams
                         ) -> types.EmptyResult:
        self._legacy.setdefault(str(params.uri), set()).add(ctx.session)
        return types.EmptyResult()

    async def _unsubscribe(self, ctx: Any, params: types.UnsubscribeRequestParams
                           ) -> types.EmptyResult:
        self._legacy.get(str(params.uri), set()).discard(ctx.session)
        return types.EmptyResult()

    @asynccontextmanager
    async def lifespan(self, app: MCPServer) -> AsyncIterator[None]:
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(self._poll)
            try:
                yield
            finally:
                tasks.cancel_scope.cancel()

    def _listened(self) -> bool:
        return self.bus.listeners > 0 or any(self._legacy.values())

    async def _poll(self) -> None:
        while True:
            await anyio.sleep(POLL_S)
            if not self._listened():
                self._seen = {}  # the first poll with a listener announces each resource
                continue
            try:
                changed = await anyio.to_thread.run_sync(self._changes)
            except Exception as exc:  # a gateway that went away: try again later
                log.debug("resource poll failed: %s", exc)
                continue
            for uri in changed:
                await self._announce(uri)

    def _changes(self) -> list[str]:
        """URIs whose value changed since the last poll."""
        now: dict[str, Any] = {}
        for product in self.gateway.products():
            if product["written"]:
                now[product_uri(product["name"])] = (product["value"], product["age_s"])
        for name, route in self.gateway.status()["routes"].items():
            if takes_frames(route["method"]):
                now[frame_uri(name)] = route["ok"]
        changed = []
        for uri, value in now.items():
            before = self._seen.get(uri)
            if isinstance(value, tuple):  # a product: a new value, or the same value again
                fresh = before is None or value[0] != before[0] or value[1] < before[1]
            else:
                fresh = value != before
            if fresh:
                changed.append(uri)
        self._seen = now
        return changed

    async def _announce(self, uri: str) -> None:
        now = anyio.current_time()
        if now - self._notified.get(uri, -MIN_NOTIFY_INTERVAL_S) < MIN_NOTIFY_INTERVAL_S:
            return
        self._notified[uri] = now
        await self.bus.publish(ResourceUpdated(uri=uri))
        for session in list(self._legacy.get(uri, ())):
            try:
                await session.send_resource_updated(uri)
            except Exception:  # the client has gone
                self._legacy[uri].discard(session)
