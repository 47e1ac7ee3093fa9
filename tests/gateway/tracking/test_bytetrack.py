"""The tracker on boxes that move as people do: ids that hold, confirmation, second-stage
matches of weak detections, dropping, labels kept apart, velocities in pixels per second."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oricf.gateway.tracking.bytetrack import ByteTracker, TrackerConfig
from oricf.imaging import Box, Detection

FPS = 10


def person(x: float, y: float = 100, score: float = 0.8, label: str = "person") -> Detection:
    return Detection(label, 0, score, Box(x, y, x + 30, y + 80))


def run(tracker: ByteTracker, frames: list[list[Detection]], start: int = 0
        ) -> list[list[Detection]]:
    return [tracker.update(f, (start + i) / FPS) for i, f in enumerate(frames)]


def test_two_walkers_keep_their_ids_and_get_their_velocities() -> None:
    tracker = ByteTracker(TrackerConfig())
    frames = [[person(100 + 5 * i), person(400 - 4 * i, 200)] for i in range(30)]
    out = run(tracker, frames)
    ids = {(round(d.box.y_min), d.track_id) for frame in out for d in frame}
    assert ids == {(100, 1), (200, 2)}
    last = {d.box.y_min: d.velocity for d in out[-1]}
    assert last[100] == pytest.approx((50, 0), abs=3)   # 5 px a frame at 10 fps
    assert last[200] == pytest.approx((-40, 0), abs=3)


def test_a_new_object_is_confirmed_after_min_hits_and_a_flash_never_is() -> None:
    tracker = ByteTracker(TrackerConfig(min_hits=3))
    run(tracker, [[person(100)]])  # the first frame's objects are confirmed at once
    out = run(tracker, [[person(100), person(400)] for _ in range(3)], start=1)
    assert [len(f) for f in out] == [1, 1, 2]
    assert out[-1][1].track_id == 2
    flash = run(tracker, [[person(100), person(600)], [person(100)], [person(100)]], start=4)
    assert all(d.track_id != 3 for f in flash for d in f)
    assert [t.track_id for t in tracker.confirmed()] == [1, 2]


def test_a_weak_detection_keeps_a_track_and_cannot_start_one() -> None:
    config = TrackerConfig(high_score=0.5, low_score=0.1, new_score=0.7)
    tracker = ByteTracker(config)
    run(tracker, [[person(100 + 5 * i)] for i in range(5)])
    weak = run(tracker, [[person(125 + 5 * i, score=0.3), person(500, score=0.3)]
                         for i in range(5)], start=5)
    assert [[d.track_id for d in f] for f in weak] == [[1]] * 5
    assert tracker.update([person(500, score=0.6)], 1.0) == []  # under new_score
    assert [t.track_id for t in tracker.confirmed()] == [1]


def test_an_unseen_track_is_kept_for_max_age_s_then_dropped() -> None:
    tracker = ByteTracker(TrackerConfig(max_age_s=1.0))
    run(tracker, [[person(100 + 5 * i)] for i in range(5)])
    run(tracker, [[] for _ in range(8)], start=5)            # 0.8 s unseen
    assert [(t.track_id, t.age_s) for t in tracker.confirmed()] == [(1, pytest.approx(1.2))]
    # back where its motion says it would be: the same id
    back = tracker.update([person(100 + 5 * 13)], 1.3)
    assert [d.track_id for d in back] == [1]
    run(tracker, [[] for _ in range(12)], start=14)          # 1.2 s unseen
    assert tracker.confirmed() == []


def test_labels_are_never_matched_across_and_only_the_configured_ones_are_tracked() -> None:
    tracker = ByteTracker(TrackerConfig(labels=["person", "dog"]))
    out = run(tracker, [[person(100), person(100, label="dog"), person(300, label="car")]
                        for _ in range(4)])
    assert sorted((d.label, d.track_id) for d in out[-1]) == [("dog", 2), ("person", 1)]


@pytest.mark.parametrize(("key", "value"), [("high_score", 0), ("min_hits", 0),
                                            ("max_age_s", -1), ("shape", 1)])
def test_bad_settings_are_refused(key: str, value: object) -> None:
    with pytest.raises(ValueError, match=key):
        TrackerConfig.model_validate({key: value})


def test_low_score_above_high_score_is_refused() -> None:
    with pytest.raises(ValueError, match=r"low_score 0\.6 is above high_score 0\.5"):
        TrackerConfig(low_score=0.6, high_score=0.5)


finite = st.floats(-1e4, 1e4, allow_nan=False)
any_float = st.one_of(finite, st.sampled_from([float("nan"), float("inf"), -float("inf"),
                                               0.0, 1e308, 1e-300, 5e-3]))


@st.composite
def detection(draw: st.DrawFn) -> Detection:
    return Detection(draw(st.sampled_from(["person", "dog"])), 0, draw(any_float),
                     Box(draw(any_float), draw(any_float), draw(any_float), draw(any_float)))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(detection(), max_size=12), max_size=15))
def test_any_detections_never_break_the_tracker(frames: list[list[Detection]]) -> None:
    """Boxes that are not finite, inverted or empty, and any score, are left out: the
    tracker neither raises nor lets them into a track."""
    tracker = ByteTracker(TrackerConfig())
    for i, frame in enumerate(frames):
        out = tracker.update([*frame, person(100 + 5 * i)], i / FPS)
        assert all(isinstance(d.track_id, int) for d in out)
        assert all(math.isfinite(v) for d in out for v in d.velocity or ())
    for track in tracker.confirmed():
        b = track.box
        assert all(math.isfinite(v) for v in (b.x_min, b.y_min, b.x_max, b.y_max))
