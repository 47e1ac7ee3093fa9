"""`oricf bench link`: the people route to an edge detector over degraded links.

The edge detector runs in a network namespace joined to this one by a veth pair (a second
host on this machine); the gateway's routing core sends it camera frames at 10 fps as JPEG,
with an onboard detector as fallback. Per link profile it prints counts per second and the
median and 90th-percentile latency from frame to count; then it cuts the link for 10 s and
prints the longest gap between counts (the failover) and how long the route took to return
to the edge once the link was back. Needs root, `ip`, `tc` and `iptables`.

Profiles: clean; 20 Mbit/s (tbf); 2% random loss (iptables); 50 +- 10 ms delay each way (a
user-space relay in a process of its own: this kernel has no netem); all three together.
Each profile runs with failover only, and with a placement policy (`placement:
{latency_budget_ms: --budget-ms}`, docs/gateway.md): the share of calls the edge answered,
the p90 against the budget and the robot's CPU per frame (this process, which runs the
gateway's routing core, plus the onboard detector process; the edge detector and the relay
are not the robot's), next to the route with the onboard detector only.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from oricf.bench.common import load_frames, print_table, stop
from oricf.bench.gateway import cpu_seconds
from oricf.bench.netns import EdgeHost, edge_host
from oricf.config import deep_merge
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, parse_pipeline
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame, Record
from oricf.hosts import Address
from oricf.launch.health import free_port, wait_serving
from oricf.stats import p90

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
# The delay relay in a process of its own, so that its CPU does not count as the robot's:
# argv upstream host, port, delay s, jitter s; prints its port, relays until terminated.
RELAY = ("import sys, threading\nfrom oricf.bench.relay import DelayRelay\n"
         "relay = DelayRelay((sys.argv[1], int(sys.argv[2])), float(sys.argv[3]), "
         "float(sys.argv[4]))\nprint(relay.port, flush=True)\nthreading.Event().wait()\n")


@dataclass
class Counts(Emitter):
    times: list[float] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)
    frames: int = 0  # fed while the robot's CPU was measured
    robot_cpu_s: float = 0.0  # over those frames

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        now = time.monotonic()
        self.times.append(now)
        self.latencies.append(now - record["sent_at"])


@contextmanager
def served(argv: list[str], address: str) -> Iterator[subprocess.Popen[bytes]]:
    """A service process (argv) until the block ends, once `address` answers SERVING."""
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_serving(address, timeout=120, process=process)
        yield process
    finally:
        stop(process)


@contextmanager
def relayed(upstream: str, delay_s: float, jitter_s: float) -> Iterator[str]:
    """The address of a delay relay process to `upstream` until the block ends."""
    address = Address.parse(upstream)
    process = subprocess.Popen([sys.executable, "-c", RELAY, address.host, str(address.port),
                                str(delay_s), str(jitter_s)], stdout=subprocess.PIPE)
    output = process.stdout
    assert output is not None
    try:
        yield f"127.0.0.1:{int(output.readline())}"
    finally:
        stop(process)
        output.close()


def oricf(*args: str) -> list[str]:
    """The command line of `oricf ARGS` with this Python."""
    return [sys.executable, "-m", "oricf", "--log-level", "WARNING", *args]


@dataclass
class Onboard:
    """The robot's detector: its address, and its process for the robot's CPU time."""

    address: str
    process: subprocess.Popen[bytes]

    def robot_cpu_s(self) -> float:
        """The robot's CPU time so far: this process (the routing core) and the onboard
        detector's."""
        return time.process_time() + cpu_seconds(self.process.pid)

    def feed(self, pipeline: Pipeline, frames: list[Frame], seconds: float,
             counts: Counts) -> None:
        """feed(), with the robot's CPU time over it added to counts."""
        started = self.robot_cpu_s()
        counts.frames += feed(pipeline, frames, seconds)
        counts.robot_cpu_s += self.robot_cpu_s() - started


@dataclass
class ProfileRun:
    counts: Counts
    pipeline: Pipeline
    cut_at: float = 0.0
    returned_after: float = 0.0


def run_profile(edge: EdgeHost, remote: str, onboard: Onboard, frames: list[Frame],
                profile: dict[str, Any], seconds: float, cut_s: float = 0.0,
                placement: dict[str, Any] | None = None) -> ProfileRun:
    with relayed(remote, profile.get("delay_s", 0.0), profile.get("jitter_s", 0.0)) as relay:
        edge.degrade(profile.get("rate_mbit"), profile.get("loss", 0.0))
        detector = {"address": relay, "fallback": onboard.address, "deadline_ms": 1500,
                    "probe_interval_s": 0.5,
                    "image": {"transport": "jpeg", "jpeg_quality": 80}}
        if placement is not None:
            detector["placement"] = placement
        data = deep_merge(ROUTE, {"endpoints": {"detector": detector}})
        counts = Counts()
        run = ProfileRun(counts, Pipeline(parse_pipeline(data, "bench link"), counts))
        run.pipeline.start()
        try:
            onboard.feed(run.pipeline, frames, seconds, run.counts)
            if cut_s:
                cut_and_return(edge, run, frames, cut_s)
        finally:
            run.pipeline.stop()
            edge.restore()
    return run


def cut_and_return(edge: EdgeHost, run: ProfileRun, frames: list[Frame], cut_s: float) -> None:
    """Cuts the link for cut_s, then feeds frames until the route is back on the edge."""
    run.cut_at = time.monotonic()
    edge.cut()
    feed(run.pipeline, frames, cut_s)
    edge.reconnect()
    back_from = time.monotonic()
    endpoint = run.pipeline.endpoints["detector"]
    while endpoint.active is not endpoint.primary and time.monotonic() - back_from < 120:
        feed(run.pipeline, frames, 0.5)
    run.returned_after = time.monotonic() - back_from
    feed(run.pipeline, frames, 2)


def feed(pipeline: Pipeline, frames: list[Frame], seconds: float) -> int:
    """Camera frames at FPS for `seconds` to the people route, each stamped `sent_at`; how
    many."""
    end, i = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        frame = frames[i % len(frames)]
        pipeline.submit("people", lambda f=frame: {"image": f, "sent_at": time.monotonic()})
        i += 1
        time.sleep(1 / FPS)
    return i


def onboard_only(onboard: Onboard, frames: list[Frame], seconds: float) -> Counts:
    counts = Counts()
    data = deep_merge(ROUTE, {"endpoints": {"detector": {"address": onboard.address}}})
    pipeline = Pipeline(parse_pipeline(data, "bench link onboard"), counts)
    pipeline.start()
    try:
        onboard.feed(pipeline, frames, seconds, counts)
    finally:
        pipeline.stop()
    return counts


def row(link: str, mode: str, counts: Counts, seconds: float, budget_ms: float,
        pipeline: Pipeline | None) -> list[Any]:
    lat = sorted(counts.latencies) or [float("nan")]
    p90_ms = p90(lat) * 1e3
    endpoint = pipeline.endpoints["detector"] if pipeline is not None else None
    answered = endpoint.answered if endpoint is not None else {"primary": 0, "fallback": 1}
    share = answered["primary"] / max(1, sum(answered.values()))
    moves = endpoint.placement.decisions["over_budget"] \
        if endpoint is not None and endpoint.placement is not None else "-"
    return [link, mode, f"{len(counts.times) / seconds:.1f}",
            f"{statistics.median(lat) * 1e3:.0f}", f"{p90_ms:.0f}",
            "yes" if p90_ms <= budget_ms else "no", f"{share:.0%}",
            f"{counts.robot_cpu_s * 1e3 / max(1, counts.frames):.1f}",
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
    onboard_address = f"127.0.0.1:{free_port()}"
    policy = {"latency_budget_ms": args.budget_ms, "window": 20, "hysteresis_s": 5,
              "probe_interval_s": 0.5}
    rows = []
    with edge_host() as edge, \
            served(edge.exec_argv(oricf("serve", "detector", "--listen",
                                        f"{edge.address}:{EDGE_PORT}")),
                   f"{edge.address}:{EDGE_PORT}"), \
            served(oricf("serve", "detector", "--listen", onboard_address),
                   onboard_address) as process:
        remote = f"{edge.address}:{EDGE_PORT}"
        onboard = Onboard(onboard_address, process)
        rows.append(row("-", "onboard only", onboard_only(onboard, frames, args.seconds),
                        args.seconds, args.budget_ms, None))
        for name, profile in PROFILES.items():
            for mode, placement in (("failover only", None), ("placement", policy)):
                run = run_profile(edge, remote, onboard, frames, profile, args.seconds,
                                  placement=placement)
                rows.append(row(name, mode, run.counts, args.seconds, args.budget_ms,
                                run.pipeline))
        cut = run_profile(edge, remote, onboard, frames, PROFILES["all three"], 5, args.cut)
    print_table(f"People route to an edge detector, {FPS} fps JPEG frames, {args.seconds:g} s "
                f"per profile, budget {args.budget_ms:g} ms",
                ["link", "mode", "counts/s", "median ms", "p90 ms", "p90 in budget",
                 "edge share", "robot CPU ms/frame", "failovers", "moves"], rows)
    print_cut(cut, args.cut)
    return 0


def print_cut(run: ProfileRun, cut_s: float) -> None:
    times = run.counts.times
    gaps = [b - a for a, b in itertools.pairwise(times) if b > run.cut_at - 2]
    endpoint = run.pipeline.endpoints["detector"]
    print(f"\nlink cut for {cut_s:g} s (profile 'all three'): longest gap between counts "
          f"{max(gaps, default=float('nan')) * 1e3:.0f} ms (failover to onboard); back on the "
          f"edge {run.returned_after:.1f} s after the link returned; failovers "
          f"{endpoint.failovers}, returns {endpoint.recoveries}")
