"""A route: input record -> method call -> post steps -> outputs. No ROS in here.

Every failure of one message is logged (throttled, per route and kind of failure) and
counted, and told to whoever asked for the record (its `reply_to`, e.g. a text channel's
client, which no output will answer now); the route goes on with the next message. Data
products go to the ProductStore; every other output to `emit` (oricf.gateway.sinks.Outlets:
files, text channels, and topics through the ROS node's publishers or a recording).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import grpc

from oricf.errors import InvalidInput
from oricf.gateway.config import OutputConfig, RouteConfig
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.methods import METHODS, Skip
from oricf.gateway.methods.base import result_fields
from oricf.gateway.post import chain
from oricf.gateway.products import ProductStore
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Record
from oricf.logs import quoted
from oricf.metrics import LatencyHistogram

log = logging.getLogger(__name__)

# (output, its value, the whole record: e.g. the input header for an annotated image)
Emit = Callable[[OutputConfig, Any, Record], None]
Loader = Callable[[], Record]
# Call errors whose details are meant for the caller (a client mistake), so they may be told.
TOLD_IN_FULL = {grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.OUT_OF_RANGE,
                grpc.StatusCode.FAILED_PRECONDITION}


class Asker(Protocol):
    """Who asked for a record (its `reply_to` field): told when the record fails."""

    def fail(self, message: str) -> None: ...


@dataclass
class RouteStats:
    ok: int = 0
    skipped: int = 0
    bad_input: int = 0
    call_errors: int = 0
    errors: dict[str, int] = field(default_factory=dict)  # kind -> count
    last_ms: float = 0.0
    latency: LatencyHistogram = field(default_factory=LatencyHistogram)  # inputs handled ok

    def count_error(self, kind: str) -> None:
        self.errors[kind] = self.errors.get(kind, 0) + 1


class Route:
    def __init__(self, name: str, config: RouteConfig, endpoint: Endpoint,
                 products: ProductStore, emit: Emit, throttle: ThrottledLog) -> None:
        self.name = name
        self.config = config
        self.endpoint = endpoint
        self.products = products
        self.stats = RouteStats()
        self._emit = emit
        self._post = chain(config.post)
        self._throttle = throttle
        self._invoke = METHODS[config.call.method].bind(config.call, endpoint, products)

    def run(self, record: Record) -> Record:
        """Call and post-process one record; returns it with every field filled in."""
        record.setdefault("route", self.name)
        record.update(result_fields(self._invoke(record)))
        self._post(record)
        return record

    def send(self, record: Record) -> None:
        for output in self.config.outputs:
            value = record.get(output.source)
            if value is None:  # e.g. no annotated image this time
                continue
            if output.product is not None:
                self.products.put(output.product, value)
            else:
                self._emit(output, value, record)

    def process(self, load: Loader) -> None:
        """Worker entry point: one message, every failure logged and counted, never raised."""
        started = time.perf_counter()
        record: Record = {}
        try:
            record = load()
            self.send(self.run(record))
        except Skip as exc:
            self.stats.skipped += 1
            log.info("route %s: nothing to send on: %s", self.name, exc)
            self._tell(record, f"nothing to answer: {exc}")
            return
        except InvalidInput as exc:
            self.stats.bad_input += 1
            self.stats.count_error("bad_input")
            self._throttle.warning(f"{self.name}:bad_input:{exc}",
                                   "route %s: bad input dropped: %s", self.name, exc)
            self._tell(record, f"bad input: {exc}")
            return
        except grpc.RpcError as exc:
            self._call_failed(exc)
            details = f": {exc.details()}" if exc.code() in TOLD_IN_FULL else ""
            self._tell(record, f"{self.config.call.method} failed: {exc.code().name}{details}")
            return
        except Exception:
            self.stats.count_error("internal")
            log.exception("route %s: unexpected error (message dropped)", self.name)
            self._tell(record, "internal error")
            return
        seconds = time.perf_counter() - started
        self.stats.ok += 1
        self.stats.last_ms = seconds * 1000
        self.stats.latency.observe(seconds)

    def _call_failed(self, exc: grpc.RpcError) -> None:
        code = exc.code()
        self.stats.call_errors += 1
        self.stats.count_error(code.name)
        self._throttle.error(f"{self.name}:{code.name}",
                             "route %s: %s call to %s (%s) failed: %s %s", self.name,
                             self.config.call.method, self.endpoint.name,
                             self.endpoint.active.address, code.name,
                             quoted(exc.details() or "", 300))  # the server's words

    @staticmethod
    def _tell(record: Record, message: str) -> None:
        asker: Asker | None = record.get("reply_to")
        if asker is not None:
            asker.fail(message[:500])
