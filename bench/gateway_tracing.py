"""`oricf bench gateway --tracing ENDPOINT`: what traces cost per frame, beside none.

The onboard gateway and the detector run twice with the same frames: without traces (the
default), then exporting them over OTLP to ENDPOINT (an OpenTelemetry backend, e.g. Arize
Phoenix: scripts/phoenix.sh; OTLP/HTTP unless OTEL_EXPORTER_OTLP_PROTOCOL says grpc). Each
run measures the latency through the gateway (and of a direct Detect call, interleaved) and
the CPU time per frame of each process (docs/tracing.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from oricf.bench.common import print_table

OTEL_VARIABLES = ("OTEL_EXPORTER_OTLP_ENDPOINT", "OTEL_EXPORTER_OTLP_TRACES_ENDPOINT")


@dataclass
class TracingRun:
    """One run: traces off or on."""

    traced: bool
    through_ms: float = 0.0
    direct_ms: float = 0.0
    lost: int = 0
    gateway_cpu_s: float = 0.0  # per processed frame
    detector_cpu_s: float = 0.0


@contextmanager
def traces_to(endpoint: str | None) -> Iterator[None]:
    """The processes started in this block export traces to endpoint (None: no traces, even
    where this process' environment names an endpoint)."""
    saved = {name: os.environ.get(name) for name in OTEL_VARIABLES}
    for name in OTEL_VARIABLES:
        os.environ.pop(name, None)
    if endpoint is not None:
        os.environ["OTEL_EXPORTER_OTLP_ENDPOINT"] = endpoint
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def tracing_table(kind: str, runs: list[TracingRun], frames: int, fps: float,
                  endpoint: str) -> None:
    off, on = (next(r for r in runs if r.traced is t) for t in (False, True))
    rows = [[name, f"{fn(off):.2f}", f"{fn(on):.2f}", f"{fn(on) - fn(off):+.2f}"]
            for name, fn in (
                ("publish -> /human_counter, median ms", lambda r: r.through_ms),
                ("direct Detect call, median ms", lambda r: r.direct_ms),
                ("added by the gateway, ms", lambda r: r.through_ms - r.direct_ms),
                ("gateway CPU ms per frame", lambda r: r.gateway_cpu_s * 1e3),
                ("detector CPU ms per frame", lambda r: r.detector_cpu_s * 1e3),
                ("gateway + detector CPU ms per frame",
                 lambda r: (r.gateway_cpu_s + r.detector_cpu_s) * 1e3))]
    print_table(f"Traces off and on, {kind} input, {frames} frames per phase (latency: "
                f"median, interleaved with direct calls; CPU at {fps:g} fps); traces to "
                f"{endpoint} ({off.lost} and {on.lost} frames without a count)",
                ["", "traces off", "traces on", "difference"], rows)
