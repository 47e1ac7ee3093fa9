"""`oricf bench offload`: the paper's offloading experiment on one machine.

A 'robot' and an 'edge' are two CPU sets of this machine (--robot-cpus, --edge-cpus: one CPU
each by default), by cgroup cpusets where possible, else taskset (oricf.bench.cpusets). On
the robot run a network camera (vtest.avi as MJPEG over HTTP at --fps: oricf.bench.
mjpeg_camera) and `oricf gateway` without ROS (configs/pipelines/text_questions.yaml, reading
the camera). The detector and the language model run on the robot (placement onboard, the
shipped placement/onboard.yaml) or on the edge (placement edge, the shipped placement/
edge.yaml: frames sent as JPEG; the onboard fallbacks it names are not started). Phases:

  base     the camera and the gateway (its text channel open, no camera route): no inference
  CNN      the people route: every camera frame to the detector, the count kept
  CNN+LLM  and a typed question ("How many people do you see?") every --question-every s on
           the gateway's text channel, answered by the language model with the count

After --warmup s, each set's utilisation is sampled every second for --seconds: the CPU time
of the set's processes over the set's CPUs and the second (Table 2), and, like vmstat, the
busy share of the set's CPUs from /proc/stat (which counts anything else running there).
Prints Table 2 (mean, median, variance, standard deviation), the robot's load cut and energy
cut with the paper's power model beside the paper's figures, and writes figure1.png,
table2.csv, table2.md and samples.csv into --out.

--link clean|degraded puts the edge in a network namespace behind a veth pair (oricf.bench.
netns; degraded: 20 Mbit/s and 2% loss towards the edge, 50 +- 10 ms each way by a relay in
this process). Needs root for cgroups and namespaces.
"""

from __future__ import annotations

import argparse
import datetime
import logging
import os
import shlex
import signal
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from oricf.bench.cpusets import BACKENDS, CpuSet, CpuSetError, busy_jiffies, cpu_sets
from oricf.bench.entry import need
from oricf.bench.netns import EdgeHost, edge_host
from oricf.bench.offload_report import (
    FIGURE,
    PAPER,
    PHASES,
    PLACEMENTS,
    SOURCES,
    Phase,
    PowerModel,
    merge,
    print_report,
    write_csv,
    write_figure,
    write_markdown,
)
from oricf.bench.offload_robot import Questions, Robot, frames_between

log = logging.getLogger(__name__)

LINKS: dict[str, dict[str, float] | None] = {
    "none": None,
    "clean": {},
    "degraded": {"rate_mbit": 20, "loss": 0.02, "delay_s": 0.05, "jitter_s": 0.01},
}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="oricf bench offload", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("offload-results"),
                        help="folder for figure1.png, table2.csv/.md, samples.csv and logs")
    parser.add_argument("--seconds", type=float, default=60, help="sampled per phase")
    parser.add_argument("--warmup", type=float, default=5, help="before each phase's samples")
    parser.add_argument("--quick", action="store_true",
                        help="a smoke check: 10 s phases, 2 s warm-up")
    parser.add_argument("--rounds", type=int, default=1,
                        help="repeat both placements, alternating which goes first")
    parser.add_argument("--fps", type=float, default=10, help="the camera's frame rate")
    parser.add_argument("--question-every", type=float, default=5, help="seconds, CNN+LLM")
    parser.add_argument("--robot-cpus", default="0", help="e.g. 0 or 0,1")
    parser.add_argument("--edge-cpus", default="1")
    parser.add_argument("--cpusets", choices=("auto", *BACKENDS), default="auto",
                        help="how the sets are made (auto: the first that works)")
    parser.add_argument("--link", choices=tuple(LINKS), default="none",
                        help="none: the edge on this host's loopback; clean or degraded: "
                             "in a network namespace")
    parser.add_argument("--cut-phase", choices=PHASES, default=PAPER["phase"],
                        help="the phase whose cuts are the headline")
    parser.add_argument("--cut-stat", choices=("mean", "median"), default="mean")
    parser.add_argument("--cut-source", choices=tuple(SOURCES), default="processes")
    parser.add_argument("--p-idle", type=float, default=PAPER["p_idle_w"], help="W (eq. 1)")
    parser.add_argument("--p-max", type=float, default=PAPER["p_max_w"], help="W (eq. 1)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seconds, args.warmup = 10.0, 2.0
    if args.seconds < 2 or args.rounds < 1:
        parser.error("--seconds must be >= 2 and --rounds >= 1")
    return args


def cpu_list(text: str) -> list[int]:
    return [int(c) for c in text.split(",") if c.strip()]


@contextmanager
def edge_network(link: str) -> Iterator[EdgeHost | None]:
    profile = LINKS[link]
    if profile is None:
        yield None
        return
    with edge_host() as edge:
        edge.degrade(profile.get("rate_mbit"), profile.get("loss", 0.0))
        try:
            yield edge
        finally:
            edge.restore()


def sample(sets: dict[str, CpuSet], seconds: float, t0: float
           ) -> tuple[dict[str, list[float]], dict[str, list[float]], float]:
    """Each set's utilisation % every second for `seconds`: by its processes' CPU time and
    by its CPUs' busy ticks; and when the samples began (seconds since t0)."""
    util: dict[str, list[float]] = {name: [] for name in sets}
    busy: dict[str, list[float]] = {name: [] for name in sets}
    start = last_t = time.monotonic()
    last_cpu, last_ticks = {n: s.cpu_seconds() for n, s in sets.items()}, busy_jiffies()
    for k in range(1, int(seconds) + 1):
        time.sleep(max(0.0, start + k - time.monotonic()))
        now, ticks = time.monotonic(), busy_jiffies()
        for name, cpuset in sets.items():
            used = cpuset.cpu_seconds()
            share = (used - last_cpu[name]) / ((now - last_t) * len(cpuset.cpus))
            util[name].append(min(100.0, 100 * share))  # reading time and CPU is not atomic
            last_cpu[name] = used
            ran = sum(ticks[c][0] - last_ticks[c][0] for c in cpuset.cpus)
            total = sum(ticks[c][1] - last_ticks[c][1] for c in cpuset.cpus)
            busy[name].append(100 * ran / total if total else 0.0)
        last_t, last_ticks = now, ticks
    return util, busy, start - t0


def measure(robot: Robot, placement: str, phase: str, args: argparse.Namespace, t0: float,
            questions: Questions | None = None) -> Phase:
    time.sleep(args.warmup)
    begin = time.time()
    util, busy, start = sample(robot.sets, args.seconds, t0)
    end = time.time()
    result = Phase(placement, phase, float(int(args.seconds)), start, util, busy,
                   frames_between(robot.counts, begin, end), load=os.getloadavg()[0])
    if questions is not None:
        result.asked, result.answer_s = questions.between(begin, end)
        result.answered = len(result.answer_s)
    log.info("%s %s: robot %.1f%%, edge %.1f%% (processes, mean)", placement, phase,
             sum(util["robot"]) / len(util["robot"]), sum(util["edge"]) / len(util["edge"]))
    return result


def run_placement(robot: Robot, placement: str, args: argparse.Namespace, t0: float
                  ) -> list[Phase]:
    results = []
    with robot.services(placement) as endpoints:
        with robot.gateway("base", placement, endpoints):
            results.append(measure(robot, placement, "base", args, t0))
        with robot.gateway("cnn", placement, endpoints):
            robot.wait_counts()
            results.append(measure(robot, placement, "CNN", args, t0))
            with Questions(robot.channel, args.question_every) as questions:
                questions.wait_first_answer()
                results.append(measure(robot, placement, "CNN+LLM", args, t0, questions))
    return results


def preamble(args: argparse.Namespace, backend: str, phases: list[Phase], load: float,
             argv: list[str]) -> str:
    command = shlex.join(["oricf", "bench", "offload", *argv])
    during = [p.load for p in phases]
    return (f"{datetime.date.today().isoformat()}, `{command}`: {os.cpu_count()} CPUs, "
            f"robot on CPU {args.robot_cpus}, edge on CPU {args.edge_cpus} ({backend}), "
            f"link {args.link}, {int(args.seconds)} s per phase after {args.warmup:g} s, "
            f"{args.rounds} round(s); the machine's load average (1 min) {load:.2f} before, "
            f"{min(during):.2f}-{max(during):.2f} at the phases' ends.")


def interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt  # SIGTERM unwinds like Ctrl-C: processes stopped, groups removed


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    signal.signal(signal.SIGTERM, interrupt)
    args = parse_args(argv)
    need("matplotlib", "figures", FIGURE)  # before minutes of measuring
    args.out.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()[0]
    power = PowerModel(args.p_idle, args.p_max)
    phases: list[Phase] = []
    try:
        with cpu_sets({"robot": cpu_list(args.robot_cpus), "edge": cpu_list(args.edge_cpus)},
                      args.cpusets) as (backend, sets), \
                edge_network(args.link) as edge, \
                tempfile.TemporaryDirectory(prefix="oricf-offload-") as work, \
                ExitStack() as stack:
            robot = stack.enter_context(Robot(sets, edge, LINKS[args.link], Path(work),
                                              args.out / "logs", args.fps))
            t0 = time.monotonic()
            for round_ in range(args.rounds):
                order = PLACEMENTS if round_ % 2 == 0 else PLACEMENTS[::-1]
                for placement in order:
                    phases += run_placement(robot, placement, args, t0)
    except CpuSetError as exc:
        log.error("%s", exc)
        return 2
    merged = merge(phases)
    text = preamble(args, backend, phases, load, argv)
    print(f"\n{text}")
    print_report(merged, args.cut_phase, args.cut_source, args.cut_stat, power)
    write_csv(merged, phases, args.out)
    write_markdown(merged, args.cut_phase, args.cut_source, args.cut_stat, power, text,
                   args.out)
    figure = write_figure(phases, merged, args.cut_source, args.out)
    print(f"\nwrote {figure}, {args.out / 'table2.csv'}, {args.out / 'table2.md'}, "
          f"{args.out / 'samples.csv'}")
    return 0
