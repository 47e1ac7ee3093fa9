"""`oricf bench link`: the people route to an edge detector over degraded links.

The edge detector runs in a network namespace joined to this one by a veth pair (a second
host on this machine); the gateway's routing core sends it camera frames at 10 fps as JPEG,
with an onboard detector as fallback. Per link profile it prints counts per second and the
median and 90th-percentile latency from frame to count; then it cuts the link for 10 s and
prints the longest gap between counts (the failover) and how long the route took to return
to the edge once the link was back. Needs root, `ip`, `tc` and `iptables`.

Profiles: clean; 20 Mbit/s (tbf); 2% random loss (iptables); 50 +- 10 ms delay each way (a
user-space relay: this kernel has no netem); all three together. Each profile runs with
failover only, and with a placement policy (`placement: {latency_budget_ms: --budget-ms}`,
docs/gateway.md): the share of calls the edge answered and the p90 against the budget, next
to the route with the onboard detector only.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from oricf.bench.common import load_frames, print_table, stop
from oricf.bench.netns import EdgeHost, edge_host
from oricf.bench.relay import DelayRelay
from oricf.config import deep_merge
from oricf.gateway.config import OutputConfig, parse_pipeline
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame, Record
from oricf.launch.health import free_port, wait_serving

FPS = 10
EDGE_PORT = 50051
PROFILES: dict[str, dict[str, Any]] = {
    "clean": {},
    "20 Mbit/s": {"rate_mbit": 20},
    "2% loss": {"loss": 0.02},
    "50 ms delay": {"delay_s": 0.05, "jitter_s": 0.01},
    "all three": {"rate_mbit": 20, "loss": 0.02, "delay_s": 0.05, "jitter_s": 0.01},
}
ROUTE = {"routes": {"people": {
    "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
    "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
    "post": [{"count": {"label": "person", "into": "count"}}],
    "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32", "from": "count"}]}}}


@dataclass
class Counts:
    times: list[float] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)

    def __call__(self, output: OutputConfig, value: Any, record: Record) -> None:
        now = time.monotonic()
        self.times.append(now)
        self.latencies.append(now - record["sent_at"])


@contextmanager
def served(argv: list[str], address: str) -> Iterator[None]:
    """A service process (argv) until the block ends, once `address` answers SERVING."""
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_serving(address, timeout=120, process=process)
        yield
    finally:
        stop(process)


def oricf(*args: str) -> list[str]:
    """The command line of `oricf ARGS` with this Python."""
    return [sys.executable, "-m", "oricf", "--log-level", "WARNING", *args]


def run_profile(edge: EdgeHost, remote: str, onboard: str, frames: list[Frame],
                profile: dict[str, Any], seconds: float, cut_s: float = 0.0,
                placement: dict[str, Any] | None = None
                ) -> tuple[Counts, Pipeline, float, float]:
    host, _, port = remote.rpartition(":")
    relay = DelayRelay((host, int(port)), profile.get("delay_s", 0.0),
                       profile.get("jitter_s", 0.0))
    edge.degrade(profile.get("rate_mbit"), profile.get("loss", 0.0))
    detector = {"address": relay.address, "fallback": onboard, "deadline_ms": 1500,
                "probe_interval_s": 0.5, "image": {"transport": "jpeg", "jpeg_quality": 80}}
    if placement is not None:
        detector["placement"] = placement
    data = deep_merge(ROUTE, {"endpoints": {"detector": detector}})
    counts = Counts()
    pipeline = Pipeline(parse_pipeline(data, "bench link"), counts)
    pipeline.start()
    cut_at = returned_after = 0.0
    try:
        feed(pipeline, frames, seconds)
        if cut_s:
            cut_at = time.monotonic()
            edge.cut()
            feed(pipeline, frames, cut_s)
            edge.reconnect()
            back_from = time.monotonic()
            endpoint = pipeline.endpoints["detector"]
            while endpoint.active is not endpoint.primary and \
                    time.monotonic() - back_from < 120:
                feed(pipeline, frames, 0.5)
            returned_after = time.monotonic() - back_from
            feed(pipeline, frames, 2)
    finally:
        pipeline.stop()
        relay.close()
        edge.restore()
    return counts, pipeline, cut_at, returned_after


def feed(pipeline: Pipeline, frames: list[Frame], seconds: float) -> None:
    """Camera frames at FPS for `seconds` to the people route, each stamped `sent_at`."""
    end, i = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        frame = frames[i % len(frames)]
        pipeline.submit("people", lambda f=frame: {"image": f, "sent_at": time.monotonic()})
        i += 1
        time.sleep(1 / FPS)


def onboard_only(onboard: str, frames: list[Frame], seconds: float) -> Counts:
    counts = Counts()
    data = deep_merge(ROUTE, {"endpoints": {"detector": {"address": onboard}}})
    pipeline = Pipeline(parse_pipeline(data, "bench link onboard"), counts)
    pipeline.start()
    try:
        feed(pipeline, frames, seconds)
    finally:
        pipeline.stop()
    return counts


def row(link: str, mode: str, counts: Counts, seconds: float, budget_ms: float,
        pipeline: Pipeline | None) -> list[Any]:
    lat = sorted(counts.latencies) or [float("nan")]
    p90 = lat[int(0.9 * (len(lat) - 1))] * 1e3
    endpoint = pipeline.endpoints["detector"] if pipeline is not None else None
    answered = endpoint.answered if endpoint is not None else {"primary": 0, "fallback": 1}
    share = answered["primary"] / max(1, sum(answered.values()))
    moves = endpoint.placement.decisions["over_budget"] \
        if endpoint is not None and endpoint.placement is not None else "-"
    return [link, mode, f"{len(counts.times) / seconds:.1f}",
            f"{statistics.median(lat) * 1e3:.0f}", f"{p90:.0f}",
            "yes" if p90 <= budget_ms else "no", f"{share:.0%}",
            endpoint.failovers if endpoint is not None else "-", moves]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench link", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20, help="per profile")
    parser.add_argument("--cut", type=float, default=10, help="seconds the link is cut")
    parser.add_argument("--budget-ms", type=float, default=150,
                        help="the placement policy's latency budget")
    args = parser.parse_args(argv)
    frames = [Frame.from_pixels(f) for f in load_frames(20)]
    onboard = f"127.0.0.1:{free_port()}"
    policy = {"latency_budget_ms": args.budget_ms, "window": 20, "hysteresis_s": 5,
              "probe_interval_s": 0.5}
    rows = []
    with edge_host() as edge, \
            served(edge.exec_argv(oricf("serve", "detector", "--listen",
                                        f"{edge.address}:{EDGE_PORT}")),
                   f"{edge.address}:{EDGE_PORT}"), \
            served(oricf("serve", "detector", "--listen", onboard), onboard):
        remote = f"{edge.address}:{EDGE_PORT}"
        rows.append(row("-", "onboard only", onboard_only(onboard, frames, args.seconds),
                        args.seconds, args.budget_ms, None))
        for name, profile in PROFILES.items():
            for mode, placement in (("failover only", None), ("placement", policy)):
                counts, pipeline, _, _ = run_profile(edge, remote, onboard, frames, profile,
                                                     args.seconds, placement=placement)
                rows.append(row(name, mode, counts, args.seconds, args.budget_ms, pipeline))
        counts, pipeline, cut_at, returned = run_profile(
            edge, remote, onboard, frames, PROFILES["all three"], 5, args.cut)
    print_table(f"People route to an edge detector, {FPS} fps JPEG frames, {args.seconds:g} s "
                f"per profile, budget {args.budget_ms:g} ms",
                ["link", "mode", "counts/s", "median ms", "p90 ms", "p90 in budget",
                 "edge share", "failovers", "moves"], rows)
    gaps = [b - a for a, b in zip(counts.times, counts.times[1:], strict=False)
            if b > cut_at - 2]
    print(f"\nlink cut for {args.cut:g} s (profile 'all three'): longest gap between counts "
          f"{max(gaps, default=float('nan')) * 1e3:.0f} ms (failover to onboard); back on the "
          f"edge {returned:.1f} s after the link returned; failovers "
          f"{pipeline.endpoints['detector'].failovers}, returns "
          f"{pipeline.endpoints['detector'].recoveries}")
    return 0
