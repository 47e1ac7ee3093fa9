"""`oricf bench tts`, a short real run: every voice measured for short and long answers, its
audio transcribed (no timing asserted)."""

import subprocess
import sys

import pytest


@pytest.mark.bench
def test_each_voice_is_measured_side_by_side() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "--log-level", "WARNING", "bench", "tts",
         "--rounds", "1"], capture_output=True, text=True, timeout=600, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("voice"))
    assert "first audio ms" in lines[header] and "RTF" in lines[header]
    rows = [line.split() for line in lines[header + 1: header + 5]]
    assert [(row[0], row[1]) for row in rows] == [
        ("joe", "short"), ("espeak", "short"), ("joe", "long"), ("espeak", "long")]
    for row in rows:
        first_ms, p90_ms, rtf, audio_s = float(row[3]), float(row[4]), float(row[6]), float(row[7])
        assert 0 < first_ms <= p90_ms and rtf > 0 and audio_s > 1
        assert row[8].endswith("%")
