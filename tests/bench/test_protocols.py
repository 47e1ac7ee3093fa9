"""`oricf bench llm|asr --protocol grpc,openai`, short real runs: every row measured (no
timing asserted)."""

import subprocess
import sys

import pytest


@pytest.mark.bench
@pytest.mark.parametrize(("service", "options", "measures"), [
    ("llm", ["--questions", "8"], "first token ms"),
    ("asr", ["--voices", "en-us"], "transcript ms"),
])
def test_both_protocols_are_measured_side_by_side(service: str, options: list[str],
                                                   measures: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "--log-level", "WARNING", "bench", service,
         "--protocol", "grpc,openai", *options],
        capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("protocol"))
    assert measures in lines[header]
    rows = [lines[header + 1].split(), lines[header + 2].split()]
    assert [row[0] for row in rows] == ["grpc", "openai"]
    assert all(float(value) > 0 for value in rows[1][1:len(rows[1]) // 2 + 1])
