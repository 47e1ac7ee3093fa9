"""The track step and the steps that measure over tracks, as a route's YAML declares them:
detections keep their track ids, measures read the tracks, bad settings are refused with
the key's path, and a measure before any track step is refused when the pipeline loads."""

from __future__ import annotations

import json

import pytest

from oricf.errors import ConfigError
from oricf.gateway import post
from oricf.gateway.config import PostStep
from oricf.gateway.post.track import Track, TrackStep
from oricf.gateway.sinks.jsonl import jsonable
from oricf.gateway.values import Record
from oricf.imaging import Box, Detection
from tests.gateway.pipelines import people_qa


def step(**kwargs: object) -> PostStep:
    return PostStep.model_validate(kwargs)


def walker(x: float) -> Detection:
    return Detection("person", 0, 0.8, Box(x, 100, x + 30, 180))


def test_track_then_measures_over_a_walk_through_a_zone_and_across_a_line() -> None:
    now = [0.0]
    tracking = Track(TrackStep(labels=["person"]), clock=lambda: now[0])
    measures = post.PostSteps([
        step(count_tracks={"label": "person", "into": "now"}),
        step(seen_tracks={"label": "person", "window_s": 60, "into": "last_minute"}),
        step(zone={"polygon": [[200, 0], [400, 0], [400, 300], [200, 300]],
                   "measure": "entries", "into": "entered"}),
        step(zone={"polygon": [[200, 0], [400, 0], [400, 300], [200, 300]],
                   "measure": "dwell_s", "into": "dwell"}),
        step(line={"start": [300, 0], "end": [300, 300], "measure": "out", "into": "east"}),
    ])
    records: list[Record] = []
    for i in range(40):  # 10 px a frame, 10 frames a second, from x=100 to x=490
        now[0] = i / 10
        record: Record = {"detections": [walker(100 + 10 * i)]}
        tracking.run(record)
        measures.run(record)
        records.append(record)
    assert {d.track_id for r in records for d in r["detections"]} == {1}
    assert records[-1]["detections"][0].velocity == pytest.approx((100, 0), abs=5)
    last = records[-1]
    assert (last["now"], last["last_minute"], last["entered"], last["east"]) == (1, 1, 1, 1)
    # the box's bottom centre (x + 15) is inside for x in 185..385: frames 9 to 28
    assert [r["dwell"] > 0 for r in records].index(True) == 10
    assert records[28]["dwell"] == pytest.approx(1.9)
    assert records[29]["dwell"] == 0
    # JSON lines carry what a track gives a detection
    line = json.loads(json.dumps(jsonable(last["detections"])))
    assert line[0]["track_id"] == 1 and line[0]["velocity"] == pytest.approx([100, 0], abs=5)


@pytest.mark.parametrize(("settings", "counted"), [({}, 1), ({"still_s": None}, 2)])
def test_a_still_weak_post_leaves_the_tracked_count_after_still_s(
        settings: dict[str, object], counted: int) -> None:
    now = [0.0]
    track = step(track={"labels": ["person"], **settings}).track
    assert track is not None
    tracking = Track(track, clock=lambda: now[0])
    count = post.PostSteps([step(count_tracks={"label": "person", "into": "now"})])
    post_box = Detection("person", 0, 0.62, Box(30, 110, 48, 142))
    for i in range(80):  # 8 s: a post that never moves, and a person walking
        now[0] = i / 10
        record: Record = {"detections": [post_box, walker(100 + 3 * i)]}
        tracking.run(record)
        count.run(record)
    assert record["now"] == counted
    assert len(record["detections"]) == counted


@pytest.mark.parametrize(("steps", "message"), [
    ({"zone": {"polygon": [[0, 0], [1, 1]], "measure": "inside", "into": "z"}},
     "polygon"),
    ({"zone": {"polygon": [[0, 0], [1, 1], [float("nan"), 0]], "measure": "inside", "into": "z"}},
     "finite"),
    ({"line": {"start": [0, 1e300], "end": [5, 5], "measure": "in", "into": "c"}},
     "at most 1e"),
    ({"zone": {"polygon": [[0, 0], [1, 1], [1, 0]], "measure": "people", "into": "z"}},
     "measure"),
    ({"line": {"start": [5, 5], "end": [5, 5], "measure": "in", "into": "c"}},
     "start and end are the same point"),
    ({"track": {"low_score": 0.9}}, "low_score 0.9 is above high_score"),
    ({"track": {"still_s": 0}}, "still_s"),
    ({"track": {"still_score": 1.5}}, "still_score"),
    ({"seen_tracks": {"window_s": 0, "into": "s"}}, "window_s"),
])
def test_bad_steps_are_refused_naming_the_key(steps: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        people_qa({"routes": {"people": {"post": [steps]}}})


def test_a_measure_needs_a_track_step_before_it() -> None:
    with pytest.raises(ConfigError, match=r"post\[0\].count_tracks: no field 'tracks'"):
        people_qa({"routes": {"people": {"post": [{"count_tracks": {"into": "count"}}]}}})
