"""CPU sets confine what is started in them and count its CPU time, by cgroups (whichever
version this machine has) and by taskset. Fails, rather than skips, where neither works."""

from __future__ import annotations

import sys
import time

import pytest

from oricf.bench.cpusets import CpuSetError, cpu_sets

SPIN = ("import os, time\n"
        "end = time.process_time() + 0.5\n"
        "while time.process_time() < end: pass\n"
        "print(sorted(os.sched_getaffinity(0)))")


@pytest.mark.parametrize("backend", ["auto", "taskset"])
def test_a_process_runs_on_its_sets_cpus_and_its_time_is_counted(backend: str) -> None:
    with cpu_sets({"robot": [0], "edge": [1]}, backend) as (_, sets):
        robot = sets["robot"].popen([sys.executable, "-c", SPIN], stdout=-1, text=True)
        edge = sets["edge"].popen([sys.executable, "-c", "import time; time.sleep(1.5)"])
        used = before = sets["robot"].cpu_seconds()
        while robot.poll() is None:  # taskset reads /proc/PID/stat: read while it lives
            used = sets["robot"].cpu_seconds()
            time.sleep(0.02)
        edge_used = sets["edge"].cpu_seconds()
        output, _ = robot.communicate()
        edge.wait()
    assert output.strip() == "[0]"
    assert used >= 0.3 > before
    assert edge_used < 0.2


def test_overlapping_or_missing_cpus_are_refused() -> None:
    with pytest.raises(CpuSetError, match="in another set"), \
            cpu_sets({"robot": [0], "edge": [0]}):
        pass
    with pytest.raises(CpuSetError, match="not all among"), \
            cpu_sets({"robot": [0], "edge": [4096]}):
        pass
