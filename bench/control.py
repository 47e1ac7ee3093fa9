"""`oricf bench control`: learned policies in simulators against the delay of an edge,
every way of running them side by side in one run.

The policies are declared models (PolicyModel, onnxruntime): pybullet's trained Hopper, Ant
and InvertedDoublePendulum (configs/models/policies/, one action per answer, 60.6 Hz) and,
for a metaworld v3 task, a chunk policy behaviour-cloned from its scripted expert
(bench/train_chunk_policy.py, 16 actions per answer, 80 Hz, trained once and cached); for
reacher-camera, a chunk policy that sees: the arm's joints and a top-down camera's image in
(bench/train_camera_policy.py, 8 actions per answer, 60.6 Hz, trained once and cached), the
image going with each request. Each runs through the gateway's control loop
(oricf.gateway.control) in simulated time: a round trip of `delay_ms` is
`ceil(delay_ms / step_ms)` steps, and an answer to the observation of step `t` is delivered
before the action for `t + d` (bench/control_run.py), so every figure but the CPU is the
same on any machine for the same seed.

    onboard        the policy on the robot, no delay (once per task: the reference); a
                   chunk is played through before the next is asked for
    edge-sync      a client unaware of delay: asks when its queue is dry, plays the chunk
                   from its arrival (late: shift), holds the last action meanwhile; a
                   policy of one action is pipelined (d + 1 requests out), so the robot
                   acts on observations d steps old
    edge-latest    delay-aware (late: skip), asking again as soon as an answer is in (one
    edge-weighted  request out); overlapping chunks merged latest only, weighted (0.7 new)
    edge-ensemble  or by ACT's temporal ensembling
    edge-ahead     metaworld only: a chunk policy trained to act as many steps ahead as
                   the round trip (train_chunk_policy --lead d, one per round trip, trained
                   once and cached), its chunk starting at the step it arrives at; late:
                   skip, merged latest only, asking again as soon as an answer is in
    edge-committed  metaworld only, and only when named in --modes: edge-ahead whose policy
                   also takes the d actions committed before its chunk (sent with each
                   request), behaviour-cloned then trained by DAgger through this loop
                   (train_committed_policy; minutes per round trip the first time)
    placed         where the gateway's placement puts it with a latency budget in steps
                   (--budget-steps), having timed the edge's round trip: onboard when
                   that is over the budget, else on the edge; the reason printed
    onboard-blind  a sim with cameras only, added by itself: onboard with every image
                   blanked (all zeros), so the table shows what the camera is worth

For pybullet's robots the figure is the return (no success); for metaworld and
reacher-camera, the success rate and the steps to success. `--json` writes one row per
task, mode and delay.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
from pathlib import Path

from oricf.bench.control_report import Row, print_goals, print_task, summarise
from oricf.bench.control_run import (
    BLIND,
    MODES,
    OPTIONAL_MODES,
    TRAINED_MODES,
    Episode,
    Placed,
    default_budget,
    delay_steps,
    placement,
    run_episode,
    setting,
)
from oricf.bench.entry import need
from oricf.bench.sims import Sim, open_sim, reacher_camera, sim_names
from oricf.bench.sims.pybullet import ROBOTS
from oricf.bench.wakeups import idle_note, idle_slowdown
from oricf.config import REPO_ROOT
from oricf.errors import ConfigError
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.models.policy_task import PolicyTask
from oricf.store import ModelStore

log = logging.getLogger(__name__)

DEFAULT_TASKS = ("hopper", "ant", "inverted-double-pendulum", "pick-place-v3")
PYBULLET_DELAYS_MS = (0.0, 16.5, 33.0, 66.0, 132.0)    # 0, 1, 2, 4, 8 steps at 60.6 Hz
METAWORLD_DELAYS_MS = (0.0, 25.0, 50.0, 100.0, 150.0, 200.0)  # 0-16 steps at 80 Hz
POLICIES = REPO_ROOT / "configs" / "models" / "policies"
CAMERA_TASKS = (reacher_camera.NAME,)


def parse_delays(text: str) -> list[float]:
    """`0,50,100` -> [0.0, 50.0, 100.0]; ConfigError naming a value that is not a
    non-negative number."""
    delays: list[float] = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise ConfigError(f"--delays-ms: {part.strip()!r} is not a number of "
                              f"milliseconds (e.g. --delays-ms 0,50,100)") from None
        if not math.isfinite(value) or value < 0:
            raise ConfigError(f"--delays-ms: {part.strip()}: must be 0 or more milliseconds")
        delays.append(value)
    return sorted(set(delays))


def check_tasks(tasks: list[str]) -> None:
    """ConfigError for a task that is neither a pybullet robot nor a metaworld v3 task;
    MissingPackage when it could be the latter and metaworld is not installed."""
    known = sim_names()
    for task in tasks:
        if task in known:
            continue
        need("metaworld", "dev", f"--task {task} (not a pybullet robot: a metaworld task?)")
        raise ConfigError(f"--task {task}: no such simulator; the pybullet robots are "
                          f"{', '.join(ROBOTS)}, the metaworld v3 tasks are named like "
                          f"pick-place-v3")


def declaration_of(task: str, lead: int = 0, committed: bool = False) -> Path:
    """The declaration of a pybullet robot's policy, of reacher-camera's policy that sees,
    or of the chunk policy trained for a metaworld task to act `lead` steps ahead (with
    `committed`, the one that also takes the actions committed before its chunk; the
    trained ones trained now when they are not cached)."""
    if task in ROBOTS:
        return POLICIES / f"{task}.yaml"
    if task == reacher_camera.NAME:
        from oricf.bench.train_camera_policy import trained_policy as camera_policy

        return camera_policy()
    if committed:
        from oricf.bench.train_committed_policy import committed_policy

        return committed_policy(task, lead=lead)
    from oricf.bench.train_chunk_policy import trained_policy

    return trained_policy(task, lead=lead)


def policy_rate_hz(task: str) -> float:
    policy = load_declaration(declaration_of(task)).task
    assert isinstance(policy, PolicyTask), task
    return policy.rate_hz


def load_policy(task: str, lead: int = 0, committed: bool = False) -> PolicyModel:
    """The task's declared policy (declaration_of), loaded."""
    policy = PolicyModel(load_declaration(declaration_of(task, lead, committed)),
                         ModelStore())
    policy.load()
    return policy


def task_modes(task: str, modes: list[str]) -> list[str]:
    """The modes run for `task`: those that need a policy trained for the round trip
    (edge-ahead) only where there is a trainer (metaworld); for a sim with cameras, also
    onboard-blind (the policy without them)."""
    metaworld = task not in ROBOTS and task not in CAMERA_TASKS
    kept = [m for m in modes if metaworld or m not in TRAINED_MODES]
    return [*kept, BLIND] if task in CAMERA_TASKS else kept


def ahead_policies(task: str, runs: list[tuple[str, int]], policy: PolicyModel
                   ) -> dict[tuple[str, int], PolicyModel]:
    """The policy each run of a trained mode uses, by mode and round trip in steps: one
    trained to act that many steps ahead (edge-committed: and to take the actions committed
    before its chunk); at no delay, the policy itself."""
    return {(mode, d): (load_policy(task, d, mode == "edge-committed") if d else policy)
            for mode, d in runs if mode in TRAINED_MODES}


def plan(modes: list[str], steps: dict[float, int], placements: dict[float, Placed]
         ) -> list[tuple[str, int]]:
    """The runs to make, as (mode, round trip in steps): onboard once, each edge mode once
    per distinct round trip (delays of as many steps give the same episodes), and what a
    placed policy runs as."""
    runs = [("onboard", 0), *([(BLIND, 0)] if BLIND in modes else [])]
    for ms, d in steps.items():
        wanted = [m for m in modes if m not in ("onboard", BLIND, "placed")]
        if "placed" in modes:
            wanted.append(placements[ms].mode)
        runs += [(m, 0 if m == "onboard" else d) for m in wanted]
    return list(dict.fromkeys(runs))


def measure_task(task: str, delays_ms: list[float], args: argparse.Namespace) -> list[Row]:
    sim: Sim = open_sim(task)
    policy = load_policy(task)
    ahead: dict[tuple[str, int], PolicyModel] = {}
    try:
        chunk = policy.task.chunk
        budget = default_budget(chunk) if args.budget_steps is None else args.budget_steps
        steps = {ms: delay_steps(ms, sim.rate_hz) for ms in delays_ms}
        placements = {ms: placement(ms, sim.rate_hz, budget, chunk) for ms in delays_ms}
        modes = task_modes(task, args.modes)
        runs = plan(modes, steps, placements)
        ahead = ahead_policies(task, runs, policy)
        max_steps = args.max_steps or sim.max_steps
        episodes: dict[tuple[str, int], list[Episode]] = {run: [] for run in runs}
        for i in range(args.episodes):  # interleaved, episode by episode (the CPU figures)
            for mode, d in runs:
                used = ahead[mode, d] if mode in TRAINED_MODES else policy
                episodes[mode, d].append(run_episode(sim, used, setting(mode, d, chunk),
                                                     args.seed + i, max_steps))
        metaworld = task not in ROBOTS
        rows = [summarise(task, mode, 0.0, 0, episodes[mode, 0], metaworld)
                for mode in ("onboard", BLIND) if (mode, 0) in episodes]
        for ms, d in steps.items():
            for mode in [m for m in modes if m not in ("onboard", BLIND)]:
                placed = placements[ms] if mode == "placed" else None
                run_as = placed.mode if placed else mode
                row = summarise(task, mode, ms, d, episodes[run_as, 0 if run_as == "onboard"
                                                            else d], metaworld)
                if placed:
                    row.placed_onboard, row.reason = placed.onboard, placed.reason
                    row.budget_steps = budget
                rows.append(row)
        return rows
    finally:
        for trained in ahead.values():
            if trained is not policy:
                trained.close()
        policy.close()
        sim.close()


def measure_realtime(task: str, delays_ms: list[float], args: argparse.Namespace) -> list[Row]:
    """The task in real time, through the relay (needs ROS 2's Python packages)."""
    need("rclpy", "ros", "oricf bench control --realtime")
    from oricf.bench.control_realtime import Plan, realtime_rows

    executors = ("python", "events") if args.executor == "both" else (args.executor,)
    rate_hz = policy_rate_hz(task)
    plans = [Plan("edge-latest", declaration_of(task), tuple(delays_ms))]
    for mode in [m for m in task_modes(task, args.modes) if m in TRAINED_MODES]:
        plans += [Plan(mode, declaration_of(task, d, mode == "edge-committed"), (ms,))
                  for ms in delays_ms if (d := delay_steps(ms, rate_hz))]
    return realtime_rows(task, plans, args.episodes, args.seed, task not in ROBOTS,
                         args.max_steps, executors)


def parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oricf bench control", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", action="append", help="a pybullet robot (hopper, ant, "
                        "inverted-double-pendulum), reacher-camera, or a metaworld v3 task "
                        "(pick-place-v3, ...); repeatable (default: " + ", ".join(DEFAULT_TASKS)
                        + ")")
    parser.add_argument("--delays-ms", type=str, default=None,
                        help="round trips to the edge, e.g. 0,50,100 (default: "
                        f"{','.join(f'{d:g}' for d in PYBULLET_DELAYS_MS)} for pybullet's "
                        "robots and reacher-camera, "
                        f"{','.join(f'{d:g}' for d in METAWORLD_DELAYS_MS)} for "
                        "metaworld)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per mode and delay")
    parser.add_argument("--seed", type=int, default=0, help="the first episode's seed")
    parser.add_argument("--modes", type=str, default=",".join(MODES),
                        help="comma-separated, of " + ", ".join(MODES + OPTIONAL_MODES) +
                        " (onboard, the reference, always runs; edge-committed only when "
                        "named: it trains a policy per round trip with DAgger)")
    parser.add_argument("--budget-steps", type=int, default=None,
                        help="the placed policy's latency budget in control steps, 1 or more "
                        "(default: 1 for a policy of one action, half a chunk for a chunk "
                        "policy)")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="cap on an episode's steps (default: the simulator's)")
    parser.add_argument("--realtime", action="store_true",
                        help="also run each task in real time over ROS 2: the policy service "
                        "behind the delay relay, the gateway's control loop in its process, "
                        "the simulator as a robot (bench/control_realtime.py); rows "
                        "realtime-onboard, realtime-edge (edge-latest's settings) and, for "
                        "edge-ahead and edge-committed when run, realtime-edge-ahead and "
                        "realtime-edge-committed")
    parser.add_argument("--executor", choices=("events", "python", "both"), default="events",
                        help="--realtime: the gateway's ROS executor (its `executor:` key): "
                        "rclpy's EventsExecutor, its Python executor, or each row on both, "
                        "side by side (default: events)")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    return parser


def options(argv: list[str] | None) -> argparse.Namespace:
    args = parser().parse_args(argv)
    args.task = args.task or list(DEFAULT_TASKS)
    check_tasks(args.task)
    args.delays = parse_delays(args.delays_ms) if args.delays_ms is not None else None
    args.modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    unknown = [m for m in args.modes if m not in MODES + OPTIONAL_MODES]
    if unknown or not args.modes:
        raise ConfigError(f"--modes: {', '.join(unknown) or 'none given'}: the modes are "
                          f"{', '.join(MODES + OPTIONAL_MODES)}")
    for name in ("episodes", "max_steps"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')}: must be 1 or more")
    if args.budget_steps is not None and args.budget_steps < 1:
        raise ConfigError("--budget-steps: must be 1 or more")
    return args


def main(argv: list[str] | None = None) -> int:
    args = options(argv)
    rows: list[Row] = []
    for task in args.task:
        at_pybullet_rate = task in ROBOTS or task in CAMERA_TASKS
        delays = args.delays or list(PYBULLET_DELAYS_MS if at_pybullet_rate
                                     else METAWORLD_DELAYS_MS)
        task_rows = measure_task(task, delays, args)
        if args.realtime:
            task_rows += measure_realtime(task, delays, args)
        print_task(task, task_rows)
        rows += task_rows
    if args.realtime:  # what a tick's short bursts of work cost here, to read the CPU by
        period_s = 1.0 / max(policy_rate_hz(task) for task in args.task)
        print()
        idle_note(idle_slowdown(period_s), period_s, "the loop's work per tick")
    print_goals(rows)
    if args.json is not None:
        args.json.write_text(json.dumps([row.as_dict() for row in rows], indent=1) + "\n")
        print(f"\nrows: {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
