"""`oricf bench llm|asr --protocol grpc,openai`: the same service over gRPC and over its
OpenAI-compatible HTTP API, side by side.

One real `oricf serve` process serves both (--http-listen), so both protocols reach the
same loaded model; each query is asked over every protocol in turn, the order alternating
from one query to the next, and the table shows medians. The HTTP side's overhead is the
median of the per-query differences from gRPC. Clients: the generated gRPC stub and the
official `openai` client (its own httpx connection pool, kept open as gRPC's channel is).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import grpc

from oricf.bench.common import print_table, served
from oricf.launch.health import free_port

PROTOCOLS = ("grpc", "openai")
# A query asked over one protocol -> {measure name: seconds}.
Ask = Callable[[Any], dict[str, float]]


def parse_protocols(value: str) -> list[str]:
    """--protocol grpc,openai as a list (argparse type)."""
    names = [name.strip() for name in value.split(",") if name.strip()]
    unknown = sorted(set(names) - set(PROTOCOLS))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{', '.join(unknown) or value!r}: use grpc, openai "
                                         f"or both (grpc,openai)")
    return list(dict.fromkeys(names))


@dataclass
class Measures:
    protocol: str
    seconds: dict[str, list[float]] = field(default_factory=dict)

    def add(self, measured: dict[str, float]) -> None:
        for name, value in measured.items():
            self.seconds.setdefault(name, []).append(value)


@dataclass(frozen=True)
class Endpoints:
    grpc: grpc.Channel
    openai: Any   # openai.OpenAI


@contextmanager
def both_protocols(service: str, *args: str) -> Iterator[Endpoints]:
    """A real `oricf serve SERVICE` with gRPC and HTTP, and a client for each."""
    import openai

    http = f"127.0.0.1:{free_port()}"
    with served(service, "--http-listen", http, *args) as (address, _), \
            grpc.insecure_channel(address) as channel:
        api = openai.OpenAI(base_url=f"http://{http}/v1", api_key="unused", max_retries=0,
                            timeout=60)
        try:
            yield Endpoints(channel, api)
        finally:
            api.close()


def interleave(queries: Sequence[Any], asks: dict[str, Ask], rounds: int = 1,
               reset: Callable[[], None] | None = None) -> list[Measures]:
    """Every query over every protocol, the order alternating; one warm-up each first.
    `reset` (not timed) runs before each protocol's turn, so that each meets the service in
    the same state (a language model's prompt cache: otherwise the second protocol to ask
    a query finds its prompt already evaluated)."""
    results = {name: Measures(name) for name in asks}
    for ask in asks.values():
        ask(queries[0])
    order = list(asks)
    for _ in range(rounds):
        for query in queries:
            for name in order:
                if reset is not None:
                    reset()
                results[name].add(asks[name](query))
            order.reverse()
    return list(results.values())


def report(title: str, results: list[Measures], measures: Sequence[str]) -> None:
    base = results[0]
    header = ["protocol", *(f"{m} ms" for m in measures), *(f"{m} +ms" for m in measures)]
    rows = []
    for r in results:
        medians = [f"{statistics.median(r.seconds[m]) * 1e3:.1f}" for m in measures]
        overheads = [f"{_overhead(base.seconds[m], r.seconds[m]) * 1e3:+.1f}"
                     for m in measures]
        rows.append([r.protocol, *medians, *overheads])
    count = len(base.seconds[measures[0]])
    print_table(f"{title}: {count} queries per protocol, interleaved; medians; +ms: the "
                f"median per-query difference from {base.protocol}", header, rows)


def _overhead(base: list[float], other: list[float]) -> float:
    return statistics.median(o - b for b, o in zip(base, other, strict=True))


def clock() -> float:
    return time.perf_counter()
