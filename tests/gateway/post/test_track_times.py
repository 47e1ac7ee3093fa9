"""The track step measures time by when each frame was taken (FRAME_TIME), not by when it is
post-processed; a frame time that goes back or leaps ahead restarts the tracks, logged,
while the time and the ids that the measures see go on."""

from __future__ import annotations

import logging

import pytest

from oricf.gateway import post
from oricf.gateway.config import PostStep
from oricf.gateway.post.track import MAX_LEAP_S, Track, TrackStep
from oricf.gateway.values import FRAME_TIME, Record
from oricf.imaging import Box, Detection


def walker(x: float, y: float = 100) -> Detection:
    return Detection("person", 0, 0.8, Box(x, y, x + 30, y + 80))


def frames(times: list[float], clock_s: float = 0.0) -> list[Record]:
    """One person walking 10 px a frame, each frame taken at its time, all post-processed
    within `clock_s` of each other (a replay as fast as it goes)."""
    step = Track(TrackStep(labels=["person"], max_age_s=1.0),
                            clock=lambda: clock_s)
    seen = post.PostSteps([PostStep.model_validate(
        {"seen_tracks": {"label": "person", "window_s": 2, "into": "seen"}})])
    records = []
    for i, taken in enumerate(times):
        record: Record = {"route": "people", FRAME_TIME: taken,
                          "detections": [walker(100 + 10 * i)]}
        step.run(record)
        seen.run(record)
        records.append(record)
    return records


def test_velocity_and_windows_follow_the_frames_times_not_the_processing() -> None:
    records = frames([i / 10 for i in range(30)])  # 10 fps, processed all at once
    assert records[-1]["detections"][0].velocity == pytest.approx((100, 0), abs=5)
    assert records[-1]["tracks"].time == pytest.approx(2.9)


def test_a_gap_longer_than_max_age_in_the_frames_times_ends_the_track() -> None:
    records = frames([0.0, 0.1, 0.2, 0.3, 1.5, 1.6, 1.7])  # 1.2 s without a frame
    ids = [{d.track_id for d in r["detections"]} for r in records]
    assert ids[3] == {1} and 1 not in ids[-1]
    assert records[4]["seen"] == 1  # the first track: still seen in the last 2 s


def test_a_frame_time_that_goes_back_restarts_the_tracks_with_new_ids(
        caplog: pytest.LogCaptureFixture) -> None:
    times = [100 + i / 10 for i in range(5)] + [3 + i / 10 for i in range(5)]
    with caplog.at_level(logging.WARNING):
        records = frames(times)
    assert "route people: frame time went back by 97.400 s: tracks start again" in caplog.text
    route_times = [r["tracks"].time for r in records]
    assert route_times == sorted(route_times)  # the measures' time never goes back
    before = {d.track_id for r in records[:5] for d in r["detections"]}
    after = {d.track_id for r in records[6:] for d in r["detections"]}
    assert before and after and not before & after
    assert records[-1]["seen"] == 2  # both tracks, each counted once


def test_a_leap_ahead_beyond_max_leap_restarts_but_a_frame_a_little_late_does_not(
        caplog: pytest.LogCaptureFixture) -> None:
    leap = [0.0, 0.1, 0.2, 0.3, 0.4, MAX_LEAP_S + 1, MAX_LEAP_S + 1.1, MAX_LEAP_S + 1.2]
    with caplog.at_level(logging.WARNING):
        records = frames(leap)
    assert "frame time went ahead by" in caplog.text
    assert records[5]["tracks"].time == pytest.approx(0.4)  # the leap took no time
    caplog.clear()
    late = frames([0.0, 0.1, 0.2, 0.15, 0.3, 0.4])  # one frame out of order
    assert not caplog.text
    assert [r["tracks"].time for r in late] == pytest.approx([0, 0.1, 0.2, 0.2, 0.3, 0.4])
    assert {d.track_id for r in late[2:] for d in r["detections"]} == {1}


def test_records_without_a_frame_time_are_timed_when_processed() -> None:
    now = [0.0]
    step = Track(TrackStep(labels=["person"]), clock=lambda: now[0])
    for i in range(10):
        now[0] = i / 5
        record: Record = {"detections": [walker(100 + 10 * i)]}
        step.run(record)
    assert record["detections"][0].velocity == pytest.approx((50, 0), abs=5)
