"""`oricf bench edge`, short, for real: two detector processes (batching off and on), a real
gateway process for one robot and the load generator for the other, JPEG frames of the
pedestrian video. Checks that every row is measured and every frame answered, never how
fast (benchmarks are commands, not timed assertions)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest


@pytest.mark.bench
def test_a_short_run_measures_every_row_and_answers_the_frames() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "oricf", "bench", "edge", "--robots", "1,2", "--gateways", "1",
         "--seconds", "3", "--rounds", "1"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    table = done.stdout.split("robots  batching  answered/s", 1)[1].split("\n\n", 1)[0]
    rows = {(cells[0], cells[1]): cells for cells in
            (re.split(r"\s{2,}", line.strip()) for line in table.splitlines()[1:])}
    assert set(rows) == {("1", "off"), ("1", "on"), ("2", "off"), ("2", "on")}, table
    for (robots, config), cells in rows.items():
        answered, errors, cpu = float(cells[2]), int(cells[6]), float(cells[7].rstrip("%"))
        # A robot sends 10 frames a second; nearly all of them are answered on any machine.
        assert answered >= 0.8 * 10 * int(robots), cells
        assert errors == 0 and cpu > 0, cells
        # The batching configuration reports its batches from the detector's /metrics.
        assert (cells[8] == "-") == (config == "off"), cells
    assert re.search(r"batching off: at 10 fps with p99 <= 100 ms, up to \d+ robots",
                     done.stdout)
