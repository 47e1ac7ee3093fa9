"""Tracking runs on recorded time: a recording of the pedestrian video, replayed as fast as
the detector goes (--rate 0) and at the recorded pace (--rate 1), gives the same tracks and
the same "people seen in the last seconds" for the same frames, however fast each replay
went. Frame times come from the header stamps, or from the log times of a camera that
leaves its stamps zero."""

from __future__ import annotations

import json
import re
from collections.abc import Container
from pathlib import Path

import cv2
import yaml
from mcap_ros2.writer import Writer

from oricf.config import config_dir, read_yaml
from oricf.gateway.topics import cdr
from oricf.gateway.topics import definitions as msgdefs
from oricf.gateway.topics.codec import input_record, timed
from oricf.gateway.values import FRAME_TIME
from tests.gateway.recording.test_record_replay import gateway_without_ros
from tests.support.data import video_frames
from tests.support.services import RunningService

# Every other frame of the first 8 s of vtest.avi (10 fps): a camera at 5 fps, twice the
# seen window, so people leave it while others stay. The first comes LEAD_NS before the
# rest: the detector's first call is slow (its connection, its warm-up), and frames that
# came meanwhile would be dropped at the recorded pace.
FRAMES = list(range(0, 80, 2))
PERIOD_NS = 200_000_000
LEAD_NS = 2_000_000_000
START_NS = 1_700_000_000_000_000_000
WINDOW_S = 4


def pipeline(folder: Path, detector: str) -> Path:
    """people_qa.yaml's camera route with a track step, its measures on topics."""
    data = read_yaml(config_dir() / "pipelines" / "people_qa.yaml")
    data.pop("profiles", None)
    data["endpoints"] = {"detector": {**data["endpoints"]["detector"], "address": detector,
                                      "deadline_ms": 60_000}}
    data["routes"] = {"people": {
        "input": {"topic": "camera/image_raw", "type": "sensor_msgs/CompressedImage"},
        "call": {"service": "detector", "method": "Detect", "labels": ["person"],
                 "min_score": 0.1},
        "post": [{"track": {"labels": ["person"], "max_age_s": 1.0}},
                 {"count_tracks": {"label": "person", "into": "now"}},
                 {"seen_tracks": {"label": "person", "window_s": WINDOW_S, "into": "seen"}}],
        "outputs": [{"topic": "/people_now", "type": "std_msgs/Int32", "from": "now"},
                    {"topic": "/people_seen", "type": "std_msgs/Int32", "from": "seen"}]}}
    path = folder / "tracked.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def record(path: Path, keep: Container[int] | None = None) -> list[int]:
    """FRAMES (those stamped with one of `keep`, if given) as JPEG CompressedImages stamped
    when the camera took them, logged 5 ms later; returns the stamps (ns)."""
    stamps = []
    with path.open("wb") as file:
        writer = Writer(file)
        schema = writer.register_msgdef("sensor_msgs/msg/CompressedImage",
                                        msgdefs.complete_definition("sensor_msgs/CompressedImage"))
        for i, pixels in enumerate(video_frames(FRAMES)):
            stamp = START_NS + i * PERIOD_NS + (LEAD_NS if i else 0)
            if keep is not None and stamp not in keep:
                continue
            ok, jpeg = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, 90])
            assert ok
            writer.write_message("/camera/image_raw", schema, {
                "header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                           "frame_id": "camera"},
                "format": "jpeg", "data": jpeg.tobytes()},
                log_time=stamp + 5_000_000, publish_time=stamp)
            stamps.append(stamp)
        writer.finish()
    return stamps


def replay(folder: Path, config: Path, recording: Path, rate: str
           ) -> tuple[dict[int, dict[str, int]], float]:
    """input stamp -> {now, seen} of each frame the route finished, and the seconds the
    replay took."""
    result = gateway_without_ros(folder, "--config", str(config), "--replay", str(recording),
                                 "--rate", rate)
    assert result.returncode == 0, result.stderr[-3000:]
    values: dict[int, dict[str, int]] = {}
    for line in map(json.loads, result.stdout.splitlines()):
        field = "now" if line["topic"] == "/people_now" else "seen"
        values.setdefault(line["input_ns"], {})[field] = line[field]
    played = re.search(r"messages played in ([\d.]+) s", result.stderr)
    assert played is not None, result.stderr[-3000:]
    return values, float(played[1])


def test_replays_at_any_rate_track_on_recorded_time(detector: RunningService,
                                                    tmp_path: Path) -> None:
    config, recording = pipeline(tmp_path, detector.address), tmp_path / "camera.mcap"
    stamps = record(recording)
    fast, fast_s = replay(tmp_path, config, recording, "0")
    paced, paced_s = replay(tmp_path, config, recording, "1")
    recorded_s = (len(FRAMES) * PERIOD_NS + LEAD_NS) / 1e9
    assert list(fast) == stamps  # --rate 0: every frame, in order
    assert fast_s < recorded_s * 0.8 <= paced_s, (fast_s, paced_s)
    seen = [fast[s]["seen"] for s in stamps]
    # Tracks come and go: more people were seen in the whole run than in one window.
    assert max(seen) >= 4 and len(set(seen)) >= 3, seen
    if list(paced) != stamps:
        # Frames that came while the detector was busy were dropped, as live. The tracker
        # saw fewer frames; given those same frames as fast as it goes, it must track
        # exactly as it did at the recorded pace.
        assert set(paced) <= set(stamps)
        subset = tmp_path / "paced_frames.mcap"
        assert record(subset, keep=set(paced)) == list(paced)
        fast, _ = replay(tmp_path, config, subset, "0")
    assert paced == fast


def stamped_frame(sec: int, nanosec: int) -> bytes:
    """A 64x48 sensor_msgs/Image of vtest.avi, serialized, with this stamp."""
    pixels = video_frames([0], (64, 48))[0]
    return cdr.write("sensor_msgs/Image", {
        "header": cdr.header(cdr.Stamp(sec, nanosec, "camera")), "height": 48, "width": 64,
        "encoding": "bgr8", "is_bigendian": 0, "step": 64 * 3, "data": pixels.tobytes()})


def test_a_frame_is_timed_by_its_stamp_or_else_when_it_was_recorded() -> None:
    stamped = timed(lambda: input_record("sensor_msgs/Image", stamped_frame(12, 500_000_000)),
                    99 * 10**9)
    assert stamped()[FRAME_TIME] == 12.5
    unstamped = timed(lambda: input_record("sensor_msgs/Image", stamped_frame(0, 0)),
                      99 * 10**9)
    assert unstamped()[FRAME_TIME] == 99.0
