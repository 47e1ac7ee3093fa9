"""The two judgements on a track's matches: a new track is confirmed on the mean score of
its last min_hits matches, and a still thing that scores weakly (a post that looks a little
like a person) is kept but not reported, while a person standing in clear view is."""

from __future__ import annotations

from oricf.gateway.tracking.bytetrack import ByteTracker, TrackerConfig
from oricf.imaging import Box, Detection

FPS = 10


def box_at(x: float, score: float, y: float = 100) -> Detection:
    return Detection("person", 0, score, Box(x, y, x + 30, y + 80))


def ids_per_frame(tracker: ByteTracker, frames: list[list[Detection]], start: int
                  ) -> list[set[int]]:
    out = []
    for i, frame in enumerate(frames):
        reported = tracker.update(frame, (start + i) / FPS)
        # what is reported now is among the tracks kept and reported (seen or not)
        assert {d.track_id for d in reported} <= {t.track_id for t in tracker.confirmed()}
        out.append({d.track_id for d in reported if d.track_id is not None})
    return out


def started(config: TrackerConfig) -> ByteTracker:
    """A tracker past its first frame (whose confident objects are confirmed at once)."""
    tracker = ByteTracker(config)
    assert tracker.update([box_at(600, 0.9, y=400)], 0.0) != []
    return tracker


def walker(scores: list[float]) -> list[list[Detection]]:
    return [[box_at(600 + 4 * i, 0.9, y=400), box_at(100 + 5 * i, s)]
            for i, s in enumerate(scores)]


def test_a_new_track_is_confirmed_when_the_mean_of_its_last_min_hits_scores_reaches_new_score(
        ) -> None:
    config = TrackerConfig(min_hits=2, new_score=0.6)
    # each score alone is at or above new_score in some frame, but no two in a row average it
    never = ids_per_frame(started(config), walker([0.55, 0.62, 0.55, 0.6, 0.55]), 1)
    assert all(ids == {1} for ids in never)
    # a confident match followed by a weak one (a second-stage match) averages above it
    late = ids_per_frame(started(config), walker([0.9, 0.35, 0.8]), 1)
    assert late == [{1}, {1, 2}, {1, 2}]
    # weak at first, then clear: confirmed once the last two average new_score
    rising = ids_per_frame(started(config), walker([0.5, 0.55, 0.7, 0.8]), 1)
    assert rising == [{1}, {1}, {1, 2}, {1, 2}]


def test_the_first_frames_objects_are_confirmed_at_once_only_when_they_score_new_score(
        ) -> None:
    tracker = ByteTracker(TrackerConfig(new_score=0.6))
    first = tracker.update([box_at(100, 0.65), box_at(400, 0.55)], 0.0)
    assert [d.track_id for d in first] == [1]


def still_post_and_people(seconds: float, jitter: float = 0.0) -> list[list[Detection]]:
    """A post that scores a little like a person (0.62) and never moves but for `jitter`
    pixels, a person standing still in clear view (0.8), and a person walking past who
    scores as weakly as the post."""
    frames = []
    for i in range(int(seconds * FPS)):
        shake = jitter if i % 2 else 0.0
        frames.append([box_at(30 + shake, 0.62), box_at(300, 0.8),
                       box_at(500 - 3 * i, 0.62, y=300)])
    return frames


def test_a_still_weak_thing_is_kept_but_not_reported_after_still_s() -> None:
    config = TrackerConfig(min_hits=2, new_score=0.6, still_s=5, still_motion=0.1,
                           still_score=0.7)
    tracker = ByteTracker(config)
    out = ids_per_frame(tracker, still_post_and_people(8, jitter=3), 0)
    post, standing, walking = 1, 2, 3
    assert all(standing in ids and walking in ids for ids in out[2:])
    assert all(post in ids for ids in out[2:50])    # still for less than 5 s: reported
    assert all(post not in ids for ids in out[50:])
    # kept all the while: when it moves, it is reported again under its own id
    moved = ids_per_frame(tracker, [[box_at(30 + 10 * i, 0.62), box_at(300, 0.8),
                                     box_at(260 - 3 * i, 0.62, y=300)]
                                    for i in range(1, 4)], 80)
    assert all(ids == {post, standing, walking} for ids in moved)


def test_a_thing_that_moves_more_than_still_motion_is_never_taken_for_still() -> None:
    config = TrackerConfig(still_s=5, still_motion=0.1)
    # 9 pixels back and forth on a box 80 high: more than a tenth of its height
    out = ids_per_frame(ByteTracker(config), still_post_and_people(8, jitter=9), 0)
    assert all(1 in ids for ids in out[2:])


def test_without_still_s_a_still_weak_thing_is_reported_as_any_track() -> None:
    out = ids_per_frame(ByteTracker(TrackerConfig(still_s=None)),
                        still_post_and_people(8), 0)
    assert all(ids == {1, 2, 3} for ids in out[2:])
