"""`oricf bench edge`: how many robots one edge detector serves, with and without batching.

Each robot has a 10 fps camera and sends 640x480 JPEG frames of the pedestrian video to one
edge detector (`oricf serve detector`, a process of its own on this machine), keeping at most
one frame in flight: a frame captured while a call is out waits, and a newer one replaces it
(a dropped frame), as the gateway does. Some robots are real gateway processes (the routing
core, bench/edge_robot.py); the rest come from a load generator in this process (grpc.aio,
one channel per robot, cameras out of phase). Two detector configurations run side by side,
interleaved per robot count: the shipped one with batching off, and with `batching:` on.

Per robot count and configuration it prints frames answered per second, latency from capture
to answer (median, 99th percentile; a dropped frame has none), frames dropped and calls that
failed, the detector process's CPU (100% is one core) and the mean batch it ran (from its
/metrics); then the batched-to-unbatched ratios and, per configuration, the most robots
served at 10 fps each with p99 <= 100 ms.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import psutil
import yaml
from prometheus_client.parser import text_string_to_metric_families

from oricf.bench.common import print_table, served, shipped_detector_model, variant_config
from oricf.bench.edge_load import STARTUP_S, Tally, Window, generate, jpeg_requests
from oricf.bench.edge_robot import FPS
from oricf.launch.health import free_port
from oricf.models.declaration import load_declaration
from oricf.v1 import detector_pb2

GOAL_P99_MS = 100.0
GOAL_SHARE = 0.95     # "serves a robot at 10 fps": answers at least 95% of its frames


@dataclass
class Edge:
    """A running detector configuration: its address, process and /metrics."""

    name: str
    address: str
    process: psutil.Process
    metrics_url: str

    def cpu_s(self) -> float:
        times = self.process.cpu_times()
        return times.user + times.system + times.children_user + times.children_system

    def batches(self) -> tuple[float, float]:
        """oricf_batch_size's sum and count so far ((0, 0) without batching)."""
        with urllib.request.urlopen(self.metrics_url, timeout=10) as response:
            text = response.read().decode()
        values = {s.name: s.value for f in text_string_to_metric_families(text)
                  for s in f.samples if s.name.startswith("oricf_batch_size_")}
        return values.get("oricf_batch_size_sum", 0.0), values.get("oricf_batch_size_count", 0.0)


@dataclass
class Result:
    """One row: a robot count on one configuration, one round."""

    robots: int
    config: str
    answered_per_s: float
    p50_ms: float
    p99_ms: float
    dropped: int
    captured: int
    errors: int
    cpu: float          # of one core
    mean_batch: float   # 0 without batching

    def cells(self) -> list[str]:
        return [str(self.robots), self.config, f"{self.answered_per_s:.1f}",
                f"{self.p50_ms:.0f}", f"{self.p99_ms:.0f}",
                f"{self.dropped} ({self.dropped / max(self.captured, 1):.0%})",
                str(self.errors), f"{self.cpu:.0%}",
                f"{self.mean_batch:.2f}" if self.mean_batch else "-"]

    @property
    def cpu_ms_per_answer(self) -> float:
        return self.cpu * 1e3 / max(self.answered_per_s, 1e-9)

    @property
    def meets_goal(self) -> bool:
        return self.answered_per_s >= GOAL_SHARE * self.robots * FPS and \
            self.p99_ms <= GOAL_P99_MS


def median_result(results: list[Result]) -> Result:
    """The rounds of one row: medians of each figure, drops and errors added up."""
    def mid(name: str) -> float:
        return float(statistics.median(getattr(r, name) for r in results))

    first = results[0]
    return Result(first.robots, first.config, mid("answered_per_s"), mid("p50_ms"),
                  mid("p99_ms"), sum(r.dropped for r in results),
                  sum(r.captured for r in results), sum(r.errors for r in results), mid("cpu"),
                  mid("mean_batch"))


def measure(edge: Edge, robots: int, gateways: int, seconds: float, deadline_ms: int,
            requests: list[detector_pb2.DetectRequest]) -> Result:
    window = Window(time.time() + STARTUP_S, seconds)
    real = min(gateways, robots)
    children = [subprocess.Popen(
        [sys.executable, "-m", "oricf.bench.edge_robot", "--detector", edge.address,
         "--start-at", str(window.start), "--seconds", str(seconds),
         "--deadline-ms", str(deadline_ms), "--offset", str(3 * i)],
        stdout=subprocess.PIPE) for i in range(real)]

    async def run() -> tuple[Tally, float, float]:
        load = asyncio.ensure_future(generate(edge.address, robots - real, window,
                                              deadline_ms / 1e3, requests))
        await asyncio.sleep(max(0.0, window.start - time.time()))
        cpu0, (sum0, count0) = edge.cpu_s(), edge.batches()
        await asyncio.sleep(max(0.0, window.end - time.time()))
        cpu, (sum1, count1) = edge.cpu_s() - cpu0, edge.batches()
        mean = (sum1 - sum0) / (count1 - count0) if count1 > count0 else 0.0
        return await load, cpu, mean

    tally, cpu, mean_batch = asyncio.run(run())
    for child in children:
        out, _ = child.communicate(timeout=60)
        tally.add(json.loads(out.decode().strip().splitlines()[-1]))
    lat = sorted(tally.latencies) or [float("nan")]
    return Result(robots, edge.name, len(tally.latencies) / seconds,
                  statistics.median(lat) * 1e3, lat[min(len(lat) - 1, int(0.99 * len(lat)))] * 1e3,
                  tally.dropped, tally.captured, tally.errors, cpu / seconds, mean_batch)


def model_with_threads(model: Path | None, threads: int | None, folder: Path) -> Path:
    """A declared model (the shipped detector's by default), at another thread count if
    given."""
    declared = load_declaration(model.resolve()) if model else shipped_detector_model()
    declaration = declared.model_dump(mode="json", exclude_unset=True)
    if threads is not None:
        declaration["backend"]["threads"] = threads
    path = folder / "model.yaml"
    path.write_text(yaml.safe_dump(declaration))
    return path


def ratios(rows: dict[tuple[int, str], Result]) -> list[list[str]]:
    """Per robot count: batched / unbatched answered frames, p99 and CPU per answer."""
    out = []
    for robots in sorted({robots for robots, _ in rows}):
        off, on = rows[(robots, "off")], rows[(robots, "on")]
        out.append([str(robots), f"{on.answered_per_s / max(off.answered_per_s, 1e-9):.2f}",
                    f"{on.p99_ms / max(off.p99_ms, 1e-9):.2f}",
                    f"{on.cpu_ms_per_answer / max(off.cpu_ms_per_answer, 1e-9):.2f}"])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench edge", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", default="1,2,4,8,12", help="robot counts, comma-separated")
    parser.add_argument("--gateways", type=int, default=2,
                        help="robots that are real gateway processes (the rest: generator)")
    parser.add_argument("--seconds", type=float, default=15, help="measured, per row")
    parser.add_argument("--rounds", type=int, default=2,
                        help="each row measured this often, interleaved; medians printed")
    parser.add_argument("--deadline-ms", type=int, default=1000, help="each call's deadline")
    parser.add_argument("--batching", choices=["both", "off", "on"], default="both",
                        help="the configurations measured (off alone: a model that cannot "
                             "batch, e.g. one OpenVINO runs at its file's own batch of 1)")
    parser.add_argument("--max-batch-size", type=int, default=8)
    parser.add_argument("--max-queue-delay-ms", type=float, default=5)
    parser.add_argument("--instances", type=int, default=2,
                        help="batches run at once (one per core with 1 thread each)")
    parser.add_argument("--max-concurrent-rpcs", type=int, default=32,
                        help="both configurations: each robot keeps a call open, so the "
                             "shipped limit (8) would refuse robots beyond it")
    parser.add_argument("--model", type=Path, default=None,
                        help="a declared detection model, both configurations (default: "
                             "the shipped detector's)")
    parser.add_argument("--threads", type=int, default=None,
                        help="onnxruntime intra-op threads, both configurations (default: "
                             "the declared model's)")
    args = parser.parse_args(argv)
    counts = [int(n) for n in args.robots.split(",")]
    batching = {"max_batch_size": args.max_batch_size,
                "max_queue_delay_ms": args.max_queue_delay_ms, "instances": args.instances}
    requests = jpeg_requests(20, 0)
    declared = load_declaration(args.model) if args.model else shipped_detector_model()
    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{os.cpu_count()} cores; model {declared.name}, {declared.backend.engine} threads "
          f"{args.threads or declared.backend.threads}")
    results: dict[tuple[int, str], list[Result]] = {}
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
        model = {"model": str(model_with_threads(args.model, args.threads, Path(tmp))),
                 "server": {"max_concurrent_rpcs": args.max_concurrent_rpcs}}
        edges = []
        configurations = [("off", model), ("on", {**model, "batching": batching})]
        for name, overrides in configurations:
            if args.batching not in ("both", name):
                continue
            config = variant_config("detector", overrides, Path(tmp), f"batching-{name}")
            metrics = f"127.0.0.1:{free_port()}"
            address, process = stack.enter_context(served(
                "detector", "--config", str(config), "--metrics-listen", metrics))
            edges.append(Edge(name, address, psutil.Process(process.pid),
                              f"http://{metrics}/metrics"))
        order = 0
        for _ in range(args.rounds):
            for robots in counts:
                order += 1  # interleaved, the order swapped from one row to the next
                for edge in (edges if order % 2 else edges[::-1]):
                    result = measure(edge, robots, args.gateways, args.seconds,
                                     args.deadline_ms, requests)
                    results.setdefault((robots, edge.name), []).append(result)
                    print("  " + "  ".join(result.cells()), flush=True)
    rows = {key: median_result(rounds) for key, rounds in sorted(results.items())}
    print_table(f"Robots at {FPS} fps on one edge detector ({args.gateways} real gateway "
                f"processes, the rest generated), {args.seconds:g} s per row, median of "
                f"{args.rounds} round(s); batching on: {batching}",
                ["robots", "batching", "answered/s", "p50 ms", "p99 ms", "dropped", "errors",
                 "edge CPU", "mean batch"], [r.cells() for r in rows.values()])
    if args.batching == "both":
        print_table("Batching on / off", ["robots", "answered/s", "p99", "CPU per answer"],
                    ratios(rows))
    for name in ("off", "on") if args.batching == "both" else (args.batching,):
        served_ok = [r.robots for r in rows.values() if r.config == name and r.meets_goal]
        print(f"batching {name}: at {FPS} fps with p99 <= {GOAL_P99_MS:.0f} ms, up to "
              f"{max(served_ok, default=0)} robots (of {', '.join(map(str, counts))})")
    print(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0
