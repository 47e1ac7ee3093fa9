"""What `oricf bench offload` prints and writes: Table 2 (utilisation of the robot and the
edge per phase and placement), the robot's load cut and energy cut beside the paper's, and
Figure 1, table2.csv, table2.md and samples.csv.

Power model (the paper's equations 1 and 2; both constants are flags):
    P = P_idle + (P_max - P_idle) * u        u: the robot's utilisation, 0..1
    E = P * t                                t: the phase's duration (the same for both
                                                placements, so the energy cut is P's)
    load cut = (u_onboard - u_edge) / u_onboard, energy cut = (E_onboard - E_edge) / E_onboard
"""

from __future__ import annotations

import csv
import statistics
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from oricf.bench.common import print_table
from oricf.bench.entry import need

PHASES = ("base", "CNN", "CNN+LLM")
FIGURE = "Figure 1 of oricf bench offload"
PLACEMENTS = ("onboard", "edge")
SETS = ("robot", "edge")
SOURCES = {"processes": "CPU time of the set's processes", "cpus": "busy share of the set's "
           "CPUs from /proc/stat, whatever runs there (vmstat-like)"}

# The paper's published figures, kept in this one place. Source: A. Meseguer Valenzuela and
# L. M. Bartolín Arnau, "ORICF -- Open Robotics Inference and Control Framework",
# arXiv:2605.09656 (2026): the robot-side load cut and estimated energy cut by offloading
# (its headline figures, for the CNN+LLM phase), measured with vmstat on a Jetson Orin NX
# robot, and the power model of its equations 1 and 2. Its per-phase Table 2 values are not
# reproduced here (we do not hold them), so only these are printed beside ours.
PAPER: dict[str, Any] = {
    "source": "arXiv:2605.09656",
    "robot": "NVIDIA Jetson Orin NX",
    "phase": "CNN+LLM",
    "load_cut_pct": 83.16,
    "energy_cut_pct": 65.8,
    "p_idle_w": 5.0,
    "p_max_w": 25.0,
}


@dataclass
class Phase:
    """One phase of one placement, as measured (rounds of the same pair are merged)."""

    placement: str
    phase: str
    seconds: float
    start_s: float = 0.0  # since the run began (Figure 1)
    util: dict[str, list[float]] = field(default_factory=dict)  # set -> % each second
    busy: dict[str, list[float]] = field(default_factory=dict)  # set -> % each second
    frames: int = 0       # camera frames counted by the people route
    asked: int = 0
    answered: int = 0
    answer_s: list[float] = field(default_factory=list)
    load: float = 0.0     # the machine's 1-minute load average at the phase's end

    def series(self, source: str) -> dict[str, list[float]]:
        return self.util if source == "processes" else self.busy


@dataclass(frozen=True)
class Stats:
    mean: float
    median: float
    variance: float  # sample variance (n - 1)
    std: float

    @classmethod
    def of(cls, values: list[float]) -> Stats:
        variance = statistics.variance(values) if len(values) > 1 else 0.0
        return cls(statistics.fmean(values), statistics.median(values), variance,
                   variance ** 0.5)


@dataclass(frozen=True)
class PowerModel:
    p_idle_w: float
    p_max_w: float

    def watts(self, utilisation_pct: float) -> float:
        return self.p_idle_w + (self.p_max_w - self.p_idle_w) * utilisation_pct / 100


def merge(phases: Iterable[Phase]) -> dict[tuple[str, str], Phase]:
    """(placement, phase) -> every round's samples together."""
    merged: dict[tuple[str, str], Phase] = {}
    for p in phases:
        into = merged.setdefault((p.placement, p.phase), Phase(
            p.placement, p.phase, 0.0, p.start_s, {s: [] for s in p.util},
            {s: [] for s in p.busy}))
        into.seconds += p.seconds
        for name in p.util:
            into.util[name] += p.util[name]
            into.busy[name] += p.busy[name]
        into.frames += p.frames
        into.asked += p.asked
        into.answered += p.answered
        into.answer_s += p.answer_s
    return merged


def stat(phase: Phase, source: str, name: str, which: str) -> float:
    return float(getattr(Stats.of(phase.series(source)[name]), which))


def table2(merged: dict[tuple[str, str], Phase], source: str) -> tuple[list[str], list[list[str]]]:
    header = ["phase", "CPU set", *(f"{p} {s}" for p in PLACEMENTS
                                    for s in ("mean", "median", "variance", "std"))]
    rows = []
    for phase in PHASES:
        for name in SETS:
            row = [phase, name]
            for placement in PLACEMENTS:
                s = Stats.of(merged[placement, phase].series(source)[name])
                row += [f"{s.mean:.1f}", f"{s.median:.1f}", f"{s.variance:.1f}", f"{s.std:.1f}"]
            rows.append(row)
    return header, rows


def cuts(merged: dict[tuple[str, str], Phase], source: str, which: str, power: PowerModel
         ) -> tuple[list[str], list[list[str]]]:
    """Per phase: the robot's utilisation in both placements, the load cut, power and energy
    over the phase (equations 1 and 2) and the energy cut; the paper's beside its phase."""
    header = ["phase", f"robot {which} onboard %", f"robot {which} edge %", "load cut",
              "P onboard W", "P edge W", "E onboard J", "E edge J", "energy cut",
              "paper load cut", "paper energy cut"]
    rows = []
    for phase in PHASES:
        on, off = (stat(merged[p, phase], source, "robot", which) for p in PLACEMENTS)
        seconds = merged["onboard", phase].seconds
        p_on, p_off = power.watts(on), power.watts(off)
        paper = ([f"{PAPER['load_cut_pct']:.2f}%", f"{PAPER['energy_cut_pct']:.1f}%"]
                 if phase == PAPER["phase"] else ["", ""])
        rows.append([phase, f"{on:.1f}", f"{off:.1f}", percent_cut(on, off), f"{p_on:.2f}",
                     f"{p_off:.2f}", f"{p_on * seconds:.0f}", f"{p_off * seconds:.0f}",
                     percent_cut(p_on, p_off), *paper])
    return header, rows


def percent_cut(before: float, after: float) -> str:
    return f"{(before - after) / before * 100:.1f}%" if before > 0 else "n/a"


def headline(merged: dict[tuple[str, str], Phase], phase: str, source: str, which: str,
             power: PowerModel) -> str:
    def both(statistic: str) -> str:
        on, off = (stat(merged[p, phase], source, "robot", statistic) for p in PLACEMENTS)
        return (f"{percent_cut(on, off)} and {percent_cut(power.watts(on), power.watts(off))} "
                f"(robot {statistic} {on:.1f}% onboard, {off:.1f}% offloaded)")

    other = "median" if which == "mean" else "mean"
    return (f"Offloading cut the robot's load and its estimated energy by {both(which)} in "
            f"{phase}; by the {other}, {both(other)}. The paper, in {PAPER['phase']}: "
            f"{PAPER['load_cut_pct']:.2f}% and {PAPER['energy_cut_pct']:.1f}%.")


def activity(merged: dict[tuple[str, str], Phase]) -> tuple[list[str], list[list[str]]]:
    header = ["placement", "phase", "seconds", "frames counted/s", "questions asked",
              "answered", "answer median s"]
    rows = []
    for (placement, phase), p in merged.items():
        answer = f"{statistics.median(p.answer_s):.2f}" if p.answer_s else "-"
        rows.append([placement, phase, f"{p.seconds:.0f}", f"{p.frames / p.seconds:.1f}",
                     str(p.asked), str(p.answered), answer])
    return header, rows


def paper_implied(power: PowerModel) -> str:
    """The paper's two headline cuts read through equations 1 and 2 at equal durations:
    the onboard and offloaded utilisations they imply (derived here, not quoted)."""
    load, energy = PAPER["load_cut_pct"] / 100, PAPER["energy_cut_pct"] / 100
    span = power.p_max_w - power.p_idle_w
    on = energy * power.p_idle_w / (span * (load - energy))
    return (f"Read through equations 1 and 2 (P_idle {power.p_idle_w:g} W, P_max "
            f"{power.p_max_w:g} W, equal durations), the paper's two cuts imply a robot at "
            f"{on * 100:.1f}% onboard and {on * (1 - load) * 100:.1f}% offloaded in "
            f"{PAPER['phase']} (derived, not quoted).")


def print_report(merged: dict[tuple[str, str], Phase], phase: str, source: str, which: str,
                 power: PowerModel) -> None:
    for name in SOURCES:
        print_table(f"Table 2: utilisation % of each CPU set, per second ({SOURCES[name]})",
                    *table2(merged, name))
    print_table(f"Robot load and energy cut by offloading ({which}, {SOURCES[source]}; "
                f"P = {power.p_idle_w:g} + ({power.p_max_w:g} - {power.p_idle_w:g}) u W, "
                f"E = P t; paper: {PAPER['source']}, {PAPER['robot']})",
                *cuts(merged, source, which, power))
    print(headline(merged, phase, source, which, power))
    print(paper_implied(power))
    print_table("What the robot did in each phase", *activity(merged))


def write_csv(merged: dict[tuple[str, str], Phase], phases: list[Phase], out: Path) -> None:
    with (out / "table2.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["placement", "phase", "cpu_set", "source", "samples", "mean",
                         "median", "variance", "std"])
        for (placement, phase), p in merged.items():
            for source in SOURCES:
                for name, values in p.series(source).items():
                    s = Stats.of(values)
                    writer.writerow([placement, phase, name, source, len(values),
                                     *(f"{v:.3f}" for v in (s.mean, s.median, s.variance,
                                                            s.std))])
    with (out / "samples.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["placement", "phase", "second", "cpu_set", "processes_pct",
                         "cpus_pct"])
        for p in phases:
            for name in p.util:
                for i, (u, b) in enumerate(zip(p.util[name], p.busy[name], strict=True)):
                    writer.writerow([p.placement, p.phase, f"{p.start_s + i + 1:.0f}", name,
                                     f"{u:.2f}", f"{b:.2f}"])


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join([*lines, *("| " + " | ".join(row) + " |" for row in rows)])


def write_markdown(merged: dict[tuple[str, str], Phase], phase: str, source: str,
                   which: str, power: PowerModel, preamble: str, out: Path) -> None:
    parts = [f"# oricf bench offload\n\n{preamble}\n"]
    for name in SOURCES:
        parts.append(f"## Table 2: utilisation % per second, {SOURCES[name]}\n\n"
                     f"{markdown_table(*table2(merged, name))}\n")
    parts.append(f"## Robot load and energy cut ({which}, {SOURCES[source]})\n\n"
                 f"{markdown_table(*cuts(merged, source, which, power))}\n\n"
                 f"{headline(merged, phase, source, which, power)}\n\n"
                 f"{paper_implied(power)}\n")
    parts.append(f"## What the robot did\n\n{markdown_table(*activity(merged))}\n")
    (out / "table2.md").write_text("\n".join(parts))


def write_figure(phases: list[Phase], merged: dict[tuple[str, str], Phase], source: str,
                 out: Path) -> Path:
    """Figure 1: each set's utilisation second by second through the phases, onboard and
    offloaded (the first round), and the robot's mean per phase with its std."""
    need("matplotlib", "figures", FIGURE)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), gridspec_kw={"width_ratios": [3, 3, 2]})
    for ax, placement in zip(axes, PLACEMENTS, strict=False):
        first = [p for p in phases if p.placement == placement][:len(PHASES)]
        t0 = first[0].start_s
        for name, colour in zip(SETS, ("tab:red", "tab:blue"), strict=True):
            for k, p in enumerate(first):  # one line per phase: no line across the gaps
                ys = p.series(source)[name]
                ax.plot([p.start_s - t0 + i + 1 for i in range(len(ys))], ys, color=colour,
                        linewidth=1, label=f"{name} CPU set" if k == 0 else None)
        for p in first:
            start = p.start_s - t0
            ax.axvline(start, color="grey", linewidth=0.5)
            ax.text(start + 0.5, 102, p.phase, fontsize=8, va="bottom")
        ax.set(title=f"placement: {placement}", xlabel="s", ylabel="utilisation %",
               ylim=(0, 112))
        ax.legend(loc="center left", fontsize=8)
    bars = axes[2]
    width = 0.38
    for k, (placement, colour) in enumerate(zip(PLACEMENTS, ("tab:red", "tab:green"),
                                                strict=True)):
        stats = [Stats.of(merged[placement, ph].series(source)["robot"]) for ph in PHASES]
        bars.bar([i + (k - 0.5) * width for i in range(len(PHASES))],
                 [s.mean for s in stats], width, yerr=[s.std for s in stats], capsize=3,
                 color=colour, label=f"placement {placement}")
    bars.set_xticks(range(len(PHASES)), PHASES)
    bars.set(title="robot, mean and std", ylabel="utilisation %", ylim=(0, 105))
    bars.legend(fontsize=8)
    fig.tight_layout()
    path = out / "figure1.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
