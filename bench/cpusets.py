"""CPU sets for `oricf bench offload`: a 'robot' and an 'edge' on one machine, each a set of
CPUs that the processes started in it are confined to, and the CPU time those processes use.

The first of these that works here is used (or the one asked for):
- cgroup2: a group per set under /sys/fs/cgroup, cpuset.cpus the set's CPUs; CPU time from
  the group's cpu.stat usage_usec. The cpuset controller is enabled for the root's children
  (+cpuset in its cgroup.subtree_control; it stays on, which changes no other group's CPUs).
- cgroup1: the cpuset and cpuacct hierarchies mounted apart (/sys/fs/cgroup/cpuset,
  /sys/fs/cgroup/cpuacct); a group per set in each; CPU time from cpuacct.usage (ns).
- taskset: `taskset -c CPUS` (affinity only); CPU time from /proc/PID/stat of the processes
  started (utime + stime, and cutime + cstime of their waited-for children), in clock ticks.

A process enters its set before it runs a line of its own (a shell writes its PID into the
group, then execs it), so its threads and children are in the set from the start. A group
counts the CPU time of everything in it, exited children included, in nanoseconds; neither
way counts other work on those CPUs (the machine may be shared). `busy_jiffies` reads the
per-CPU counters of /proc/stat, which count everything on a CPU, as vmstat does.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import time
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

CGROUP = Path("/sys/fs/cgroup")
BACKENDS = ("cgroup2", "cgroup1", "taskset")
ENTER = 'for f in $ORICF_CGROUP_PROCS; do echo $$ > "$f" || exit 97; done; exec "$@"'


class CpuSetError(RuntimeError):
    """No way to confine processes to CPUs here (or the CPUs asked for do not exist)."""


class CpuSet:
    """A named set of CPUs: processes started in it, and their CPU time so far."""

    def __init__(self, name: str, cpus: Sequence[int]) -> None:
        self.name = name
        self.cpus = tuple(cpus)

    @property
    def cpu_list(self) -> str:
        return ",".join(map(str, self.cpus))

    def popen(self, argv: list[str], **kwargs: Any) -> subprocess.Popen[Any]:
        raise NotImplementedError

    def cpu_seconds(self) -> float:
        raise NotImplementedError


class CgroupSet(CpuSet):
    def __init__(self, name: str, cpus: Sequence[int], groups: Sequence[Path], usage: Path
                 ) -> None:
        super().__init__(name, cpus)
        self.groups = tuple(dict.fromkeys(groups))  # v2: one group; v1: cpuset and cpuacct
        self.usage = usage

    def popen(self, argv: list[str], **kwargs: Any) -> subprocess.Popen[Any]:
        env = {**kwargs.pop("env", os.environ),
               "ORICF_CGROUP_PROCS": " ".join(str(g / "cgroup.procs") for g in self.groups)}
        return subprocess.Popen(["sh", "-c", ENTER, "sh", *argv], env=env, **kwargs)

    def cpu_seconds(self) -> float:
        text = self.usage.read_text()
        if self.usage.name == "cpu.stat":
            fields = dict(line.split() for line in text.splitlines())
            return int(fields["usage_usec"]) / 1e6
        return int(text) / 1e9


class TasksetSet(CpuSet):
    def __init__(self, name: str, cpus: Sequence[int]) -> None:
        super().__init__(name, cpus)
        self._seen: dict[int, float] = {}  # pid -> its CPU seconds when last read

    def popen(self, argv: list[str], **kwargs: Any) -> subprocess.Popen[Any]:
        process = subprocess.Popen(["taskset", "-c", self.cpu_list, *argv], **kwargs)
        self._seen[process.pid] = 0.0
        return process

    def cpu_seconds(self) -> float:
        for pid in self._seen:
            try:
                self._seen[pid] = process_cpu_seconds(pid, children=True)
            except OSError:
                continue  # ended: its last reading stands
        return sum(self._seen.values())


def process_cpu_seconds(pid: int, children: bool = False) -> float:
    """CPU time of a process from /proc/PID/stat (utime + stime; with `children`, also
    cutime + cstime of its waited-for children); OSError once it has ended."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    # after the name: state is field 3, utime..cstime are fields 14-17
    return sum(int(v) for v in fields[11:15 if children else 13]) / os.sysconf("SC_CLK_TCK")


def busy_jiffies() -> dict[int, tuple[int, int]]:
    """Per CPU: (busy, total) clock ticks since boot from /proc/stat; idle and iowait are
    not busy (vmstat's `id` and `wa`)."""
    cpus: dict[int, tuple[int, int]] = {}
    for line in Path("/proc/stat").read_text().splitlines():
        name, *values = line.split()
        if name.startswith("cpu") and name[3:].isdigit():
            ticks = [int(v) for v in values[:8]]  # user..steal; guest is inside user
            cpus[int(name[3:])] = (sum(ticks) - ticks[3] - ticks[4], sum(ticks))
    return cpus


@contextmanager
def cpu_sets(wanted: dict[str, Sequence[int]], backend: str = "auto"
             ) -> Iterator[tuple[str, dict[str, CpuSet]]]:
    """(the backend used, a CpuSet per name); groups are removed on exit, after the caller
    has stopped its processes."""
    _check_cpus(wanted)
    tried: list[str] = []
    for name in BACKENDS if backend == "auto" else (backend,):
        with ExitStack() as stack:
            try:
                sets = _make(name, wanted, stack)
            except (OSError, CpuSetError) as exc:
                tried.append(f"{name}: {exc}")
                continue
            log.info("CPU sets by %s: %s", name, ", ".join(
                f"{s.name} on CPU {s.cpu_list}" for s in sets.values()))
            yield name, sets
            return
    raise CpuSetError("cannot confine processes to CPU sets here (" + "; ".join(tried) + "); "
                      "run as root where /sys/fs/cgroup has the cpuset controller, or "
                      "install taskset (util-linux)")


def _check_cpus(wanted: dict[str, Sequence[int]]) -> None:
    allowed = os.sched_getaffinity(0)
    seen: set[int] = set()
    for name, cpus in wanted.items():
        if not cpus or not set(cpus) <= allowed:
            raise CpuSetError(f"{name}: CPUs {list(cpus)} are not all among this process's "
                              f"CPUs {sorted(allowed)}")
        if seen & set(cpus):
            raise CpuSetError(f"{name}: CPUs {sorted(seen & set(cpus))} are in another set")
        seen |= set(cpus)


def _make(backend: str, wanted: dict[str, Sequence[int]], stack: ExitStack
          ) -> dict[str, CpuSet]:
    if backend == "taskset":
        if shutil.which("taskset") is None:
            raise CpuSetError("taskset not found")
        return {name: TasksetSet(name, cpus) for name, cpus in wanted.items()}
    tag = f"oricf-offload-{os.getpid()}"
    every = ",".join(str(c) for cpus in wanted.values() for c in cpus)
    if backend == "cgroup2":
        if "cpuset" not in (CGROUP / "cgroup.controllers").read_text().split():
            raise CpuSetError("no cpuset controller in /sys/fs/cgroup/cgroup.controllers")
        _write(CGROUP / "cgroup.subtree_control", "+cpuset")
        parent = _mkdir(CGROUP / tag, stack)
        _write(parent / "cpuset.cpus", every)
        _write(parent / "cgroup.subtree_control", "+cpuset")
        sets: dict[str, CpuSet] = {}
        for name, cpus in wanted.items():
            group = _mkdir(parent / name, stack)
            _write(group / "cpuset.cpus", ",".join(map(str, cpus)))
            sets[name] = CgroupSet(name, cpus, [group], group / "cpu.stat")
        return sets
    if backend != "cgroup1":
        raise CpuSetError(f"unknown backend {backend!r}; one of auto, {', '.join(BACKENDS)}")
    cpuset, cpuacct = CGROUP / "cpuset", CGROUP / "cpuacct"
    if not (cpuset / "cpuset.cpus").exists() or not (cpuacct / "cpuacct.usage").exists():
        raise CpuSetError("no cgroup v1 cpuset and cpuacct hierarchies under /sys/fs/cgroup")
    mems = (cpuset / "cpuset.mems").read_text().strip()
    parents = _mkdir(cpuset / tag, stack), _mkdir(cpuacct / tag, stack)
    _write(parents[0] / "cpuset.cpus", every)
    _write(parents[0] / "cpuset.mems", mems)
    sets = {}
    for name, cpus in wanted.items():
        group, acct = _mkdir(parents[0] / name, stack), _mkdir(parents[1] / name, stack)
        _write(group / "cpuset.cpus", ",".join(map(str, cpus)))
        _write(group / "cpuset.mems", mems)  # v1: both must be set before tasks join
        sets[name] = CgroupSet(name, cpus, [group, acct], acct / "cpuacct.usage")
    return sets


def _write(path: Path, text: str) -> None:
    path.write_text(text)


def _mkdir(path: Path, stack: ExitStack) -> Path:
    path.mkdir()
    stack.callback(_rmdir, path)
    return path


def _rmdir(path: Path) -> None:
    """A group can be removed once its tasks are gone, which the kernel may take a moment
    to notice after they exit."""
    for _ in range(50):
        try:
            path.rmdir()
            return
        except FileNotFoundError:
            return
        except OSError:
            time.sleep(0.1)
    log.warning("could not remove %s (processes still in it?)", path)
