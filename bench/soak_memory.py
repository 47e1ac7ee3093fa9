"""Which memory a soaked process holds, and whether it still grows once warmed up.

Resident memory (RSS) is split into anonymous pages (RssAnon: the heap, llama.cpp's
buffers, Python objects; what a leak grows) and file-backed ones (RssFile: a model's
mapped weights and the shared libraries, paged in as the run first touches them and given
back to the page cache under pressure: not a leak).

A process fills its caches and pools early and then levels off, so the question a soak
asks is not the slope over the whole run but whether memory still grows at its end. The
plateau test fits a least-squares line to each series over the run's last third (after
the warm-up): it is growing when the line's rise over that window is larger than the
window's own scatter around the line allows (twice the residuals' standard deviation,
and at least NOISE_FLOOR_MB). A longer run gives a longer window, so a slower growth.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

MB = 1e6
# The smallest rise over the window that counts as growth: the allocator and the
# interpreter move a process's RSS by a megabyte or so between samples at rest.
NOISE_FLOOR_MB = 2.0
LATE_SHARE = 1 / 3  # of the run after the warm-up: the window of the plateau test
# Fields of /proc/PID/status (kB) and the names the report gives them.
SPLIT_FIELDS = {"RssAnon": "anon", "RssFile": "file"}

Points = Sequence[tuple[float, float]]  # (seconds since the soak began, MB)


def rss_split_mb(pid: int) -> dict[str, float]:
    """{"anon": MB, "file": MB} of a process from /proc/PID/status; empty where the kernel
    does not say (not Linux, or the process is gone)."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return {}
    split = {}
    for line in lines:
        key, _, value = line.partition(":")
        if key in SPLIT_FIELDS and value.split():
            split[SPLIT_FIELDS[key]] = round(int(value.split()[0]) * 1024 / MB, 1)
    return split if len(split) == len(SPLIT_FIELDS) else {}


def slope_mb_per_h(points: Points) -> float | None:
    """The slope of a least-squares line through the points, per hour; None with fewer
    than two distinct times."""
    if len({t for t, _ in points}) < 2:
        return None
    slope, _ = statistics.linear_regression([t for t, _ in points], [m for _, m in points])
    return slope * 3600


def late_window_start(first_s: float, last_s: float, warmup_s: float) -> float:
    """Where the plateau test's window begins: the last third of the run after warm-up."""
    begin = max(first_s, warmup_s)
    return last_s - (last_s - begin) * LATE_SHARE


@dataclass(frozen=True)
class Trend:
    """A line through one memory series over the window."""

    mb_per_h: float
    rise_mb: float   # the line's rise from the window's first sample to its last
    noise_mb: float  # the rise the window's scatter accounts for

    @property
    def growing(self) -> bool:
        return self.rise_mb > self.noise_mb


def trend(points: Points) -> Trend | None:
    """The window's line and its plateau test; None with fewer than three samples (two
    points always lie on a line, so their scatter says nothing)."""
    times = [t for t, _ in points]
    if len(points) < 3 or len(set(times)) < 2:
        return None
    values = [m for _, m in points]
    slope, intercept = statistics.linear_regression(times, values)
    residuals = [m - (intercept + slope * t) for t, m in points]
    scatter = (sum(r * r for r in residuals) / (len(points) - 2)) ** 0.5
    return Trend(slope * 3600, slope * (times[-1] - times[0]),
                 max(NOISE_FLOOR_MB, 2 * scatter))
