"""Hostile recordings replayed by `oricf gateway --replay`: impossible times and rates end
with a clear line and the gateway exits; strings from the file reach the log escaped and
clipped, never as forged log lines."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mcap_ros2.writer import Writer

from oricf.config import config_dir, read_yaml
from oricf.gateway.recording.pace import MAX_GAP_NS, Pace
from oricf.gateway.recording.recorder import RecordingError
from oricf.gateway.shells.main import build_parser

IMAGE_DEFINITION = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
                    "uint8 is_bigendian\nuint32 step\nuint8[] data\n" + "=" * 80 +
                    "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
                    + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
HOSTILE_ENCODING = "\x1b[31m\nFAKE LOG LINE" + "x" * 5000


def frames(path: Path, log_times: list[int], encoding: str = "bgr8") -> None:
    """Camera frames of 2x2 pixels, at these log times."""
    with path.open("wb") as file:
        writer = Writer(file)
        image = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE_DEFINITION)
        for at in log_times:
            writer.write_message("/camera/image_raw", image, {
                "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "f"},
                "height": 2, "width": 2, "encoding": encoding, "is_bigendian": 0,
                "step": 6, "data": bytes(12)}, log_time=at, publish_time=at)
        writer.finish()


def replay(folder: Path, recording: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """The people route of people_qa.yaml, its detector nowhere (no frame here reaches it)."""
    data = read_yaml(config_dir() / "pipelines" / "people_qa.yaml")
    data["routes"] = {"people": data["routes"]["people"]}
    data["endpoints"] = {"detector": {**data["endpoints"]["detector"],
                                      "address": "127.0.0.1:9"}}
    data.pop("profiles", None)
    pipeline = folder / "pipeline.yaml"
    pipeline.write_text(yaml.safe_dump(data))
    return subprocess.run([sys.executable, "-m", "oricf", "gateway", "--config", str(pipeline),
                           "--replay", str(recording), *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("gap", [2**63, 2**64 - 2, 31 * 365 * 86400 * 10**9])
def test_an_impossible_gap_is_skipped_and_the_gateway_exits(gap: int, tmp_path: Path) -> None:
    recording = tmp_path / "gap.mcap"
    frames(recording, [1, 1 + gap] if gap < 2**64 - 1 else [1, gap])
    started = time.monotonic()
    done = replay(tmp_path, recording, "--rate", "1")
    assert time.monotonic() - started < 30
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert "of recorded time without a message (more than 60 s): skipped" in done.stderr
    assert "2 messages played" in done.stderr


@pytest.mark.parametrize("rate", ["1e-300", "-1", "1e300", "inf", "nan"])
def test_a_rate_out_of_range_is_refused_by_the_parser(rate: str) -> None:
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["--replay", "x.mcap", "--rate", rate])
    assert exit_.value.code == 2


def test_the_replay_itself_refuses_a_rate_out_of_range(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="rate 1e-300: must be 0"):
        Pace(tmp_path / "x.mcap", 1e-300)


def test_the_pace_keeps_the_recorded_timing_within_the_cap(tmp_path: Path) -> None:
    pace = Pace(tmp_path / "x.mcap", 2.0)
    assert pace.wait_s(10**9, now=100.0) == 0
    assert pace.wait_s(3 * 10**9, now=100.0) == pytest.approx(1.0)
    assert pace.wait_s(3 * 10**9 + MAX_GAP_NS, now=101.0) == pytest.approx(MAX_GAP_NS / 2e9)
    assert pace.gaps_skipped == 0
    assert pace.wait_s(2**64 - 1, now=200.0) == 0
    assert pace.wait_s(2**64 - 1, now=200.5) == 0
    assert pace.gaps_skipped == 1


def test_a_hostile_encoding_is_logged_escaped_and_clipped(tmp_path: Path) -> None:
    recording = tmp_path / "encoding.mcap"
    frames(recording, [1], encoding=HOSTILE_ENCODING)
    done = replay(tmp_path, recording, "--rate", "0")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert not any(line.startswith("FAKE LOG LINE") for line in lines)
    assert "\x1b" not in done.stderr
    dropped = [line for line in lines if "bad input dropped" in line]
    assert len(dropped) == 1 and "'\\x1b[31m\\nFAKE LOG LINE" in dropped[0]
    assert len(dropped[0]) < 600
