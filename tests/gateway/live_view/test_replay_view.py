"""The live view of a replay: `oricf gateway --replay camera.mcap --foxglove ...` in a process
of its own, without ROS, replaying a recording of vtest.avi through a tracking pipeline,
watched by the Foxglove protocol's own client: the replayed frames, their detections as
annotations (the boxes the route found for those frames, with track ids), the measures and
the data product arrive; the plumbing of a replay (frame times, input times) is not shown."""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tests.gateway.live_view.processes import gateway_with_view
from tests.gateway.live_view.viewers import official_client
from tests.gateway.recording.test_replay_times import pipeline, record
from tests.support.services import RunningService

MAX_FPS = 4.0


def viewed_pipeline(folder: Path, detector: str) -> Path:
    """The tracking pipeline of test_replay_times, its detections on a topic (JSON lines
    here) and its measure in a data product, with a live view."""
    path = pipeline(folder, detector)
    data = yaml.safe_load(path.read_text())
    data["routes"]["people"]["outputs"] += [
        {"topic": "/people_detections", "type": "vision_msgs/Detection2DArray",
         "from": "detections"},
        {"product": "people_seen", "from": "seen"}]
    data["foxglove"] = {"max_fps": MAX_FPS}
    path.write_text(yaml.safe_dump(data))
    return path


def boxes_of(lines: list[str]) -> list[set[tuple[float, ...]]]:
    """Each replayed frame's detections, as the route sent them on its topic."""
    found = []
    for line in map(json.loads, lines):
        if line["topic"] == "/people_detections":
            found.append({tuple(round(v, 2) for v in (b["box"]["x_min"], b["box"]["y_min"],
                                                      b["box"]["x_max"], b["box"]["y_max"]))
                          for b in line["detections"]})
    return found


@pytest.mark.long
def test_a_replay_is_watched_live(detector: RunningService, tmp_path: Path) -> None:
    config, recording = viewed_pipeline(tmp_path, detector.address), tmp_path / "camera.mcap"
    record(recording)
    with gateway_with_view(tmp_path, "--config", str(config), "--replay", str(recording),
                           "--rate", "1") as gateway:
        started = time.monotonic()
        got = official_client(gateway.url, seconds=6)
        elapsed = time.monotonic() - started
        assert gateway.process.wait(timeout=120) == 0, "".join(gateway.log)[-3000:]
    assert got.topics["/people/image"] == "foxglove.CompressedImage"
    assert got.topics["/people/detections"] == "foxglove.ImageAnnotations"
    for topic in ("/people/now", "/people/seen", "/products/people_seen",
                  "/endpoints/detector", "/routes/people/state"):
        assert topic in got.topics, sorted(got.topics)
    assert not {"/people/frame_time", "/people/input_publish_ns"} & set(got.topics)

    images = got.messages["/people/image"]
    assert 3 <= len(images) <= MAX_FPS * elapsed + 1
    for _, image in images:
        pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
        assert image.format == "jpeg" and pixels is not None
        assert pixels.shape == (576, 768, 3)
    sent = boxes_of(gateway.out)
    annotations = got.messages["/people/detections"]
    assert len(annotations) == len(images)
    assert sum(len(a.points) for _, a in annotations) > 0
    for _, annotation in annotations:  # each is the boxes of one replayed frame
        shown = {tuple(round(v, 2) for p in (a.points[0], a.points[2]) for v in (p.x, p.y))
                 for a in annotation.points}
        assert shown in sent
        assert all(t.text.startswith("person #") for t in annotation.texts)
    seen = [m["value"] for _, m in got.messages["/products/people_seen"]]
    assert seen and all(1 <= v <= 15 for v in seen)
