"""What `oricf bench soak` measures and reports: the resident memory (RSS, split into
anonymous and file-backed) and CPU time of each process read from /proc, the ERROR and
Traceback lines of the processes' log, each answer judged against the people count published
just before it, and the summary per process (RSS at the first sample and the last, growth
per hour by a least-squares line over the samples after the warm-up, and over the run's
last third alone with a plateau test naming the memory that still grows there: a cache that
fills and levels off is flat at the end, a leak keeps growing; soak_memory), as a table,
JSON and CSV."""

from __future__ import annotations

import csv
import json
import logging
import re
import threading
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import psutil

from oricf.bench.common import print_table
from oricf.bench.soak_memory import (
    MB,
    SPLIT_FIELDS,
    late_window_start,
    rss_split_mb,
    slope_mb_per_h,
    trend,
)

log = logging.getLogger(__name__)

# A line that reports a failure: the services' and the gateway's ERROR and CRITICAL log
# records, a Python traceback, an interpreter that died.
ERROR_LINE = re.compile(r"\b(ERROR|CRITICAL)\b|Traceback \(most recent call last\)|"
                        r"Fatal Python error")
KEPT_ERROR_LINES = 20
NUMBER_WORDS = {word: n for n, word in enumerate([
    "zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
    "eleven", "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen",
    "eighteen", "nineteen", "twenty"])}


@dataclass(frozen=True)
class Sample:
    t_s: float            # since the soak began
    process: str
    pid: int
    rss_mb: float | None  # None: the process had ended
    cpu_s: float | None   # user + system, its waited-for children's included
    anon_mb: float | None = None  # RssAnon: heap, buffers, objects (what a leak grows)
    file_mb: float | None = None  # RssFile: mapped files (a model's weights, libraries)


def read_process(name: str, pid: int, t_s: float) -> Sample:
    try:
        process = psutil.Process(pid)
        with process.oneshot():
            if process.status() == psutil.STATUS_ZOMBIE:
                return Sample(t_s, name, pid, None, None)
            rss = process.memory_info().rss
            times = process.cpu_times()
    except psutil.Error:  # gone, or not ours to read
        return Sample(t_s, name, pid, None, None)
    cpu = times.user + times.system + times.children_user + times.children_system
    split = rss_split_mb(pid)
    return Sample(round(t_s, 1), name, pid, round(rss / MB, 1), round(cpu, 2),
                  split.get("anon"), split.get("file"))


def stated_numbers(text: str) -> set[int]:
    """Every number a sentence states, in digits or words ("no one", "nobody": 0)."""
    text = re.sub(r"\bno one\b|\bnobody\b|\bno people\b", " zero ", text.lower())
    return {int(w) if w.isdigit() else NUMBER_WORDS[w] for w in re.findall(r"\d+|[a-z]+", text)
            if w.isdigit() or w in NUMBER_WORDS}


@dataclass(frozen=True)
class Answer:
    """One question: what came back, and whether the answer states the count."""

    at_s: float
    question: str
    transcript: str | None
    count: int | None   # the latest count published before the transcript arrived
    answer: str | None
    total_ms: float | None
    first_audio_ms: float | None

    @property
    def answered(self) -> bool:
        return None not in (self.transcript, self.count, self.answer)

    @property
    def right(self) -> bool:
        return self.answered and self.count in stated_numbers(str(self.answer))


class LogErrors:
    """Counts the error lines per process in the launcher's log file (`name | line`),
    reading only what was added since the last scan; the bench's own ERROR records are
    counted as `bench` (a logging handler)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.counts: Counter[str] = Counter()
        self.lines: list[str] = []  # the first few, for the report
        self._offset = 0
        self._lock = threading.Lock()

    def scan(self) -> None:
        with self._lock, self.path.open("rb") as handle:
            handle.seek(self._offset)
            data = handle.read()
            whole = data[:data.rfind(b"\n") + 1]  # a line still being written waits
            self._offset += len(whole)
        for line in whole.decode("utf-8", "replace").splitlines():
            name, _, text = line.partition(" | ")
            if ERROR_LINE.search(text):
                self.add(name.strip(), line)

    def add(self, process: str, line: str) -> None:
        self.counts[process] += 1
        if len(self.lines) < KEPT_ERROR_LINES:
            self.lines.append(line)

    def handler(self) -> logging.Handler:
        errors = self

        class Counting(logging.Handler):
            def emit(self, record: logging.LogRecord) -> None:
                errors.add("bench", f"bench | {record.levelname} {record.getMessage()}")

        return Counting(logging.ERROR)


def series(samples: list[Sample], since_s: float, memory: str = "rss"
           ) -> list[tuple[float, float]]:
    """(time, MB) of one memory ("rss", "anon" or "file") from since_s on, where read."""
    values = ((s.t_s, getattr(s, f"{memory}_mb")) for s in samples if s.t_s >= since_s)
    return [(t, mb) for t, mb in values if mb is not None]


def growth_mb_per_h(samples: list[Sample], warmup_s: float) -> float | None:
    """The slope of a least-squares line through RSS over time after the warm-up, per hour;
    None with fewer than two such samples."""
    return slope_mb_per_h(series(samples, warmup_s))


def still_growing(samples: list[Sample], since_s: float) -> list[str] | None:
    """The memories that still grow from since_s on, by the plateau test: "anon" and
    "file" where the split was read, "rss" where not; None with too few samples."""
    split = [trend(series(samples, since_s, name)) for name in SPLIT_FIELDS.values()]
    if all(found is not None for found in split):
        return [name for name, found in zip(SPLIT_FIELDS.values(), split, strict=True)
                if found is not None and found.growing]
    whole = trend(series(samples, since_s))
    if whole is None:
        return None
    return ["rss"] if whole.growing else []


@dataclass
class ProcessSummary:
    process: str
    rss_first_mb: float | None
    rss_last_mb: float | None
    anon_first_mb: float | None
    anon_last_mb: float | None
    file_first_mb: float | None
    file_last_mb: float | None
    growth_mb_per_h: float | None       # RSS, after the warm-up
    late_from_s: float                  # the last third of the run: from here to the end
    late_growth_mb_per_h: float | None  # RSS over the last third
    late_anon_mb_per_h: float | None
    late_file_mb_per_h: float | None
    still_growing: list[str] | None     # memories growing beyond noise in the last third
    cpu_s: float | None        # over the soak (last sample - first)
    cpu_share: float | None    # of one core, over the soak
    ended: bool                # gone before the last sample
    error_lines: int

    def cells(self) -> list[str]:
        def mb(value: float | None) -> str:
            return "-" if value is None else f"{value:.0f}"

        def rate(value: float | None) -> str:
            return "-" if value is None else f"{value:+.1f}"

        return [self.process, mb(self.rss_first_mb), mb(self.rss_last_mb),
                f"{mb(self.anon_first_mb)} > {mb(self.anon_last_mb)}",
                f"{mb(self.file_first_mb)} > {mb(self.file_last_mb)}",
                rate(self.growth_mb_per_h), rate(self.late_growth_mb_per_h),
                f"{rate(self.late_anon_mb_per_h)} / {rate(self.late_file_mb_per_h)}",
                self.verdict(),
                "-" if self.cpu_s is None else f"{self.cpu_s:.1f}",
                "-" if self.cpu_share is None else f"{self.cpu_share:.0%}",
                "ENDED" if self.ended else "running", str(self.error_lines)]

    def verdict(self) -> str:
        if self.still_growing is None:
            return "-"
        return f"GROWING {'+'.join(self.still_growing)}" if self.still_growing else "flat"


def summarize(samples: list[Sample], warmup_s: float, errors: Counter[str]
              ) -> list[ProcessSummary]:
    names = list(dict.fromkeys(s.process for s in samples))
    return [summarize_one([s for s in samples if s.process == name], warmup_s,
                          errors.get(name, 0)) for name in names]


def ends(alive: list[Sample], memory: str) -> tuple[float | None, float | None]:
    """One memory ("rss", "anon" or "file") at the first sample and the last."""
    if not alive:
        return None, None
    return getattr(alive[0], f"{memory}_mb"), getattr(alive[-1], f"{memory}_mb")


def summarize_one(mine: list[Sample], warmup_s: float, error_lines: int) -> ProcessSummary:
    alive = [s for s in mine if s.rss_mb is not None]
    first, last = (alive[0], alive[-1]) if alive else (None, None)
    cpu = share = None
    if first is not None and last is not None and first.cpu_s is not None \
            and last.cpu_s is not None:
        cpu = last.cpu_s - first.cpu_s
        share = cpu / (last.t_s - first.t_s) if last.t_s > first.t_s else None
    late = late_window_start(mine[0].t_s, mine[-1].t_s, warmup_s)
    return ProcessSummary(
        mine[0].process, *ends(alive, "rss"), *ends(alive, "anon"), *ends(alive, "file"),
        growth_mb_per_h(mine, warmup_s), late, growth_mb_per_h(mine, late),
        slope_mb_per_h(series(mine, late, "anon")), slope_mb_per_h(series(mine, late, "file")),
        still_growing(mine, late), cpu, share, mine[-1].rss_mb is None, error_lines)


HEADER = ["process", "RSS first MB", "RSS last MB", "anon MB", "file MB", "growth MB/h",
          "last 3rd MB/h", "anon / file MB/h", "last 3rd", "CPU s", "CPU", "state",
          "error lines"]


def print_samples(samples: list[Sample]) -> None:
    """One round of samples, one line."""
    minute = samples[0].t_s / 60
    cells = [f"{s.process} {'ended' if s.rss_mb is None else f'{s.rss_mb:.0f} MB'}"
             + ("" if s.cpu_s is None else f" {s.cpu_s:.0f} s") for s in samples]
    print(f"[{minute:5.1f} min] RSS, CPU: " + " | ".join(cells), flush=True)


def print_summary(summaries: list[ProcessSummary], answers: list[Answer],
                  warmup_s: float) -> None:
    print_table(f"Per process (RSS, anonymous and file-backed memory at the first sample > "
                f"the last; growth: a line fitted to RSS after the first {warmup_s:g} s, and "
                "to the run's last third, split; last 3rd: flat, or the memory that grows "
                "there beyond its noise)", HEADER, [s.cells() for s in summaries])
    growing = [f"{s.process} ({'+'.join(s.still_growing)})" for s in summaries
               if s.still_growing]
    print("\nstill growing in the last third: " + (", ".join(growing) if growing else "none"))
    answered = sum(a.answered for a in answers)
    wrong = sum(a.answered and not a.right for a in answers)
    print(f"\nanswered {answered}/{len(answers)} questions; {wrong} answers did not state "
          f"the count published just before; "
          f"{sum(s.error_lines for s in summaries)} error lines", flush=True)


def write_report(path: Path, report: dict[str, Any], samples: list[Sample]) -> Path:
    """The report as JSON at path, the samples as CSV beside it (same name, .csv)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2) + "\n")
    table = path.with_suffix(".csv")
    with table.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(Sample.__dataclass_fields__))
        writer.writeheader()
        writer.writerows(asdict(s) for s in samples)
    return table


@dataclass
class Outcome:
    """Everything a soak found, for the summary, the files and the exit code."""

    answers: list[Answer] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    viewer_images_per_s: float = 0.0

    def report(self, summaries: list[ProcessSummary], errors: LogErrors,
               settings: dict[str, Any]) -> dict[str, Any]:
        answered = sum(a.answered for a in self.answers)
        return {
            "settings": settings,
            "questions": {"asked": len(self.answers), "answered": answered,
                          "wrong": sum(a.answered and not a.right for a in self.answers)},
            "processes": [asdict(s) for s in summaries],
            "error_lines": {"counts": dict(errors.counts), "first": errors.lines},
            "viewer_images_per_s": round(self.viewer_images_per_s, 2),
            "answers": [{**asdict(a), "answered": a.answered, "right": a.right}
                        for a in self.answers],
            "samples": [asdict(s) for s in self.samples],
        }
