"""`oricf bench control`'s rows, its table per task and its goals, each met or not with
the figures behind it."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import asdict, dataclass

from oricf.bench.common import print_table
from oricf.bench.control_run import Episode, delay_steps
from oricf.bench.sims import reacher_camera
from oricf.stats import percentile

EDGE_MODES = ("edge-sync", "edge-latest", "edge-weighted", "edge-ensemble", "edge-ahead",
              "edge-committed")
HOPPER_EDGE_MS = 30.0   # the goal's edge for Hopper, at a one-step budget
PYBULLET_HZ = 1 / 0.0165


@dataclass
class Row:
    task: str
    mode: str
    delay_ms: float
    delay_steps: int
    episodes: int
    success_rate: float | None          # metaworld; None for pybullet (no success, a return)
    mean_return: float
    mean_steps: float | None            # to success (metaworld: successes only), else length
    action_age_p50: float | None        # steps from an action's observation to its tick
                                        # (a held action's too)
    action_age_p99: float | None
    empty_ticks: float                  # per episode
    late_actions: float                 # per episode
    switches: float                     # per episode
    mean_jump: float | None             # max |a_t - a_t-1| at a switch, mean over switches
    cpu_us_per_tick: float              # the robot side's, median over episodes
    budget_steps: int | None = None     # placed only
    # realtime only: the loop's own work on its threads (oricf_gateway_control_cpu_seconds)
    loop_cpu_us_per_tick: float | None = None
    loop_tick_cpu_us: float | None = None   # of which the ticks', per tick
    request_cpu_us: float | None = None     # and the requests', per request
    executor: str | None = None             # realtime only: the gateway's ROS executor
    placed_onboard: bool | None = None
    reason: str | None = None

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def _mean(values: Sequence[float]) -> float | None:
    return statistics.fmean(values) if values else None


def summarise(task: str, mode: str, delay_ms: float, delay_steps: int,
              episodes: list[Episode], metaworld: bool) -> Row:
    ages = [age for e in episodes for age in e.ages]
    switches = sum(e.counts.switches for e in episodes)
    jump = sum(e.counts.jump_sum for e in episodes) / switches if switches else None
    successes = [e for e in episodes if e.success]
    steps = [e.steps for e in (successes if metaworld else episodes)]
    return Row(
        task, mode, delay_ms, delay_steps, len(episodes),
        len(successes) / len(episodes) if metaworld else None,
        statistics.fmean(e.total_return for e in episodes), _mean(steps),
        percentile(ages, 50) if ages else None, percentile(ages, 99) if ages else None,
        statistics.fmean(e.counts.empty_ticks for e in episodes),
        statistics.fmean(e.counts.late_actions for e in episodes),
        statistics.fmean(e.counts.switches for e in episodes), jump,
        statistics.median(e.cpu_ns / max(e.ticks, 1) / 1e3 for e in episodes))


def _figure(value: float | None, form: str = ".0f") -> str:
    return "-" if value is None else format(value, form)


def _mode(row: Row) -> str:
    return f"{row.mode} ({row.executor})" if row.executor else row.mode


def print_task(task: str, rows: list[Row]) -> None:
    metaworld = rows[0].success_rate is not None
    header = ["mode", "delay ms", "steps d", *(["success"] if metaworld else []), "return",
              "steps to success" if metaworld else "steps", "age p50/p99", "empty ticks",
              "late actions", "switches", "jump", "CPU us/tick"]
    table = [[_mode(row), f"{row.delay_ms:g}", row.delay_steps,
              *([f"{row.success_rate:.0%}"] if row.success_rate is not None else []),
              f"{row.mean_return:.1f}", _figure(row.mean_steps, ".1f"),
              f"{_figure(row.action_age_p50)}/{_figure(row.action_age_p99)}",
              f"{row.empty_ticks:.1f}", f"{row.late_actions:.1f}", f"{row.switches:.1f}",
              _figure(row.mean_jump, ".3f"), f"{row.cpu_us_per_tick:.0f}"]
             for row in rows]
    print_table(f"{task}: {rows[0].episodes} episodes per row (onboard once, at no delay; "
                f"figures per episode)", header, table)
    for row in rows:
        if row.reason:
            print(f"  placed at {row.delay_ms:g} ms: {row.reason}")
        if row.loop_cpu_us_per_tick is not None:
            print(f"  {_mode(row)} at {row.delay_ms:g} ms: the loop's own work "
                  f"{row.loop_cpu_us_per_tick:.0f} us a tick of the {row.cpu_us_per_tick:.0f} "
                  f"us the robot side's processes took (the tick itself "
                  f"{_figure(row.loop_tick_cpu_us)} us, a request {_figure(row.request_cpu_us)} "
                  f"us)")


@dataclass(frozen=True)
class Goal:
    name: str
    status: str                 # met, not met, not measured
    figures: str


def _onboard(rows: list[Row], task: str) -> Row | None:
    return next((r for r in rows if r.task == task and r.mode == "onboard"), None)


def _best_edge(rows: list[Row], task: str, delay_ms: float) -> Row | None:
    """The edge mode that did best for `task` at `delay_ms`: most successes, then fewest
    steps (the highest return for pybullet)."""
    edge = [r for r in rows if r.task == task and r.delay_ms == delay_ms
            and r.mode in EDGE_MODES]
    if not edge:
        return None
    return max(edge, key=lambda r: (r.success_rate or 0.0, -(r.mean_steps or 1e9),
                                    r.mean_return))


def _rate(row: Row) -> str:
    steps = "" if row.mean_steps is None else f" in {row.mean_steps:.0f} steps"
    return f"{row.mode} {row.success_rate:.0%}{steps}"


def metaworld_goal(rows: list[Row], delay_ms: float, share: float, steps_ratio: float | None,
                   tasks: list[str]) -> Goal:
    name = (f"{', '.join(tasks) or 'metaworld'} behind {delay_ms:g} ms: success >= "
            f"{share:.0%} of onboard's" + (f", steps <= {steps_ratio:g}x" if steps_ratio else ""))
    pairs = [(_onboard(rows, t), _best_edge(rows, t, delay_ms)) for t in tasks]
    measured = [(o, e) for o, e in pairs if o is not None and e is not None]
    if not tasks or len(measured) < len(tasks):
        return Goal(name, "not measured", f"no row at {delay_ms:g} ms")
    met, figures = True, []
    for onboard, edge in measured:
        assert onboard.success_rate is not None and edge.success_rate is not None
        met &= edge.success_rate >= share * onboard.success_rate
        if steps_ratio and onboard.mean_steps and edge.success_rate:
            met &= (edge.mean_steps or 0) <= steps_ratio * onboard.mean_steps
        figures.append(f"{onboard.task}: {_rate(onboard)}, {_rate(edge)}")
    return Goal(name, "met" if met else "not met", "; ".join(figures))


def hopper_goal(rows: list[Row]) -> Goal:
    steps = delay_steps(HOPPER_EDGE_MS, PYBULLET_HZ)
    name = (f"hopper, budget 1 step, a {HOPPER_EDGE_MS:g} ms edge ({steps} steps): kept "
            f"onboard, return >= 95% of onboard's")
    placed = next((r for r in rows if r.task == "hopper" and r.mode == "placed"
                   and r.delay_steps == steps and r.budget_steps == 1), None)
    onboard = _onboard(rows, "hopper")
    if placed is None or onboard is None:
        return Goal(name, "not measured", f"no placed row at {steps} steps with budget 1")
    met = bool(placed.placed_onboard) and placed.mean_return >= 0.95 * onboard.mean_return
    return Goal(name, "met" if met else "not met",
                f"at {placed.delay_ms:g} ms: return {placed.mean_return:.0f} against "
                f"onboard's {onboard.mean_return:.0f}; {placed.reason}")


def cpu_goal(rows: list[Row]) -> Goal:
    name = "the loop's robot-side CPU per tick, policy offloaded: <= 500 us"
    figures, worst = [], 0.0
    for task in dict.fromkeys(r.task for r in rows):
        edge = [r.cpu_us_per_tick for r in rows if r.task == task and r.mode in EDGE_MODES]
        onboard = _onboard(rows, task)
        if not edge or onboard is None:
            continue
        loop = statistics.median(edge)
        worst = max(worst, max(edge))
        figures.append(f"{task}: {loop:.0f} us offloaded (median of the edge rows), "
                       f"{onboard.cpu_us_per_tick:.0f} us onboard "
                       f"({loop / onboard.cpu_us_per_tick:.2f}x)")
    realtime = [r for r in rows
                if r.mode.startswith("realtime-edge") and r.loop_cpu_us_per_tick is not None]
    if not figures and not realtime:
        return Goal(name, "not measured", "no edge rows")
    if realtime:  # measured on the loop's threads in real time: it counts too
        figures.append("in real time, the loop's own work: " + ", ".join(
            f"{r.task} at {r.delay_ms:g} ms ({r.executor}) {r.loop_cpu_us_per_tick:.0f} us"
            for r in realtime))
        worst = max(worst, *(r.loop_cpu_us_per_tick or 0.0 for r in realtime))
    return Goal(name, "met" if worst <= 500 else "not met",
                f"worst {worst:.0f} us; " + "; ".join(figures))


def goals(rows: list[Row]) -> list[Goal]:
    metaworld = list(dict.fromkeys(r.task for r in rows if r.success_rate is not None
                                   and r.task != reacher_camera.NAME))
    pick_place = [t for t in metaworld if t == "pick-place-v3"]
    return [metaworld_goal(rows, 100.0, 0.9, 1.3, pick_place),
            metaworld_goal(rows, 50.0, 0.95, None, metaworld),
            hopper_goal(rows), cpu_goal(rows)]


def print_goals(rows: list[Row]) -> None:
    print("\nGoals (the best edge mode at each delay; simulated time, so all but the CPU "
          "hold on any machine for these seeds)")
    for goal in goals(rows):
        print(f"- {goal.status.upper()}: {goal.name}\n    {goal.figures}")
