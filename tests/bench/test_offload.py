"""`oricf bench offload --quick` for real: a robot and an edge CPU set, the camera, the
gateway, the detector and the language model in both placements. Needs root for the
cgroups (else taskset); a machine where neither works fails here, by design."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from oricf.bench.offload_report import PHASES, PLACEMENTS, SETS, SOURCES


def run_quick(out: Path) -> str:
    done = subprocess.run([sys.executable, "-m", "oricf", "bench", "offload", "--quick",
                           "--out", str(out)], capture_output=True, text=True, timeout=400)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.mark.bench
def test_quick_run_writes_table_2_and_figure_1(tmp_path: Path) -> None:
    stdout = run_quick(tmp_path)
    assert (tmp_path / "figure1.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Table 2" in (tmp_path / "table2.md").read_text()
    assert "load cut" in stdout and "energy cut" in stdout

    with (tmp_path / "table2.csv").open() as f:
        rows = list(csv.DictReader(f))
    table = {(r["placement"], r["phase"], r["cpu_set"], r["source"]): r for r in rows}
    assert set(table) == {(p, ph, s, src) for p in PLACEMENTS for ph in PHASES
                          for s in SETS for src in SOURCES}
    for row in rows:
        assert 0 <= float(row["mean"]) <= 100 and 0 <= float(row["median"]) <= 100, row
        assert int(row["samples"]) >= 9, row

    def robot(placement: str, phase: str) -> float:
        return float(table[placement, phase, "robot", "processes"]["mean"])

    # Counting people costs the robot CPU onboard; offloading the detector takes most of it.
    assert robot("onboard", "CNN") > robot("onboard", "base")
    assert robot("edge", "CNN") < robot("onboard", "CNN")
    # Onboard, nothing runs in the edge set; offloaded, the edge does the inference.
    assert float(table["onboard", "CNN", "edge", "processes"]["mean"]) == 0
    assert float(table["edge", "CNN", "edge", "processes"]["mean"]) > 0

    with (tmp_path / "samples.csv").open() as f:
        for sample in csv.DictReader(f):
            assert 0 <= float(sample["processes_pct"]) <= 100, sample
            assert 0 <= float(sample["cpus_pct"]) <= 100, sample
