"""`oricf bench providers`: the detector's model on each provider setup, side by side; a
provider that is not here falls back and the table says where each setup ran."""

from __future__ import annotations

import pytest

from oricf.bench.providers import main


def test_each_setup_is_measured_and_says_where_it_ran(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--frames", "8", "--batch", "1,4", "--cpu-threads", "2"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()
            if line.startswith(("cpu ", "cpu-all", "cuda "))]
    setups = [(row[0], row[1] if row[0] != "cpu-all" else row[2]) for row in rows]
    # cuda has no provider on this machine: it ran on the CPU, as its row says.
    assert setups == [("cpu", "CPUExecutionProvider")] * 2 + [
        ("cpu-all", "CPUExecutionProvider")] * 2 + [("cuda", "CPUExecutionProvider")] * 2
    for row in rows:
        batch, ms, agree = int(row[-6]), float(row[-5]), row[-1]
        assert batch in (1, 4) and ms > 0 and agree == "8/8"
