"""The live view end to end: the people_video pipeline on vtest.avi with the real detector,
watched by the Foxglove protocol's own client (npm @foxglove/ws-protocol under Node.js) and
by viewers that stop reading."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from oricf.imaging import Detection
from tests.gateway.live_view.support import (
    Running,
    running,
    video_pipeline,
)
from tests.gateway.live_view.viewers import official_client, stalled_viewer, watch
from tests.support.services import RunningService

MAX_FPS = 4.0


@pytest.fixture()
def gateway(detector: RunningService) -> Iterator[Running]:
    with running(video_pipeline(detector.address, {"max_fps": MAX_FPS})) as run:
        yield run


def boxes(points: list[object]) -> set[tuple[float, ...]]:
    return {tuple(round(v, 2) for p in [a.points[0], a.points[2]] for v in (p.x, p.y))  # type: ignore[attr-defined]
            for a in points}


def detection_boxes(detections: list[Detection]) -> set[tuple[float, ...]]:
    return {tuple(round(v, 2) for v in (d.box.x_min, d.box.y_min, d.box.x_max, d.box.y_max))
            for d in detections}


def test_the_official_client_sees_frames_and_annotations_that_match_the_detections(
        gateway: Running) -> None:
    started = time.monotonic()
    got = official_client(gateway.url, seconds=6)
    elapsed = time.monotonic() - started
    assert got.topics["/people/image"] == "foxglove.CompressedImage"
    assert got.topics["/people/detections"] == "foxglove.ImageAnnotations"
    for topic in ("/people/count", "/products/people_count", "/endpoints/detector",
                  "/routes/people/state"):
        assert topic in got.topics, sorted(got.topics)

    images = got.messages["/people/image"]
    assert 3 <= len(images) <= MAX_FPS * elapsed + 1  # the cap holds whatever the load
    for _, image in images:
        assert image.format == "jpeg" and image.frame_id == "people"
        pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
        assert pixels.shape == (576, 768, 3)

    # Every annotation message is one frame's detections: its boxes, its captions.
    sent = [r["detections"] for r in gateway.records]
    annotations = got.messages["/people/detections"]
    # One per image; the client's reading stops at a moment, which can fall between the
    # last frame's image and its annotation.
    assert abs(len(annotations) - len(images)) <= 1
    assert sum(len(a.points) for _, a in annotations) >= 3
    for ns, annotation in annotations:
        shown = boxes(list(annotation.points))
        match = next(d for d in sent if detection_boxes(d) == shown)
        assert sorted(t.text for t in annotation.texts) == sorted(
            f"{d.label} {d.score:.2f}" for d in match)
        assert annotation.points and all(p.type == 2 for p in annotation.points)  # LINE_LOOP
        assert any(ns == image_ns for image_ns, _ in images)  # sent with its frame

    counts = [m["value"] for _, m in got.messages["/people/count"]]
    assert counts and all(0 <= c <= 15 for c in counts)
    endpoint = got.messages["/endpoints/detector"][-1][1]
    assert endpoint["active"] == gateway.pipeline.endpoints["detector"].primary.address
    assert endpoint["on_fallback"] is False and endpoint["latency_ms"] > 0


TRACKING = [{"track": {"labels": ["person"]}},
            {"count_tracks": {"label": "person", "into": "count"}},
            {"seen_tracks": {"label": "person", "window_s": 60, "into": "seen"}}]


def test_tracked_people_carry_their_track_ids_and_the_tracking_measures_are_plotted(
        detector: RunningService) -> None:
    with running(video_pipeline(detector.address, {"max_fps": MAX_FPS}, post=TRACKING)) \
            as tracked:
        got = official_client(tracked.url, seconds=6)
    captions = [t.text for _, a in got.messages["/people/detections"] for t in a.texts]
    ids = {d.track_id for r in tracked.records for d in r["detections"]}
    assert captions and all(re.fullmatch(r"person #\d+ \d\.\d\d", c) for c in captions)
    assert {int(c.split("#")[1].split()[0]) for c in captions} <= ids
    seen = [m["value"] for _, m in got.messages["/people/seen"]]
    assert seen and seen == sorted(seen)  # unique people in the last minute: never fewer


def test_a_viewer_that_stops_reading_costs_the_robot_nothing(gateway: Running) -> None:
    """One viewer subscribes to the frames and never reads again; the route goes on and a
    second viewer still gets frames. (What the stalled viewer costs the gateway's memory is
    measured on a gateway process of its own: test_stalled_viewer.py.)"""
    stats = gateway.pipeline.routes["people"].stats
    with stalled_viewer(gateway.url, "/people/image"):
        time.sleep(2)  # the stalled viewer's buffers fill
        before_ok = stats.ok
        # Watched until both are there; the timeout only keeps a broken run from hanging.
        images = watch(gateway.url, seconds=60,
                       enough=lambda got: got >= 10 and stats.ok - before_ok >= 20)
        handled = stats.ok - before_ok
        assert handled >= 20, handled
        assert images >= 10, images
    # The gateway still takes viewers afterwards.
    assert watch(gateway.url, seconds=30, enough=lambda got: got >= 2) >= 2
