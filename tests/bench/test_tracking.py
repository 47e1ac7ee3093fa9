"""Count quality on people counted by hand: the real detector service on every frame of
vtest.avi, counted per frame and through the `track` and `count_tracks` steps.

The tracker's defaults were chosen on the tuning set, so what holds on the held-out set is
what the tracker can be trusted with: there, as on the tuning set, the tracked count both
errs less and flickers less than counting each frame on its own. With ByteTrack's own
settings, which keep no still thing out of the count, it flickers less too."""

from __future__ import annotations

import itertools

import pytest

from oricf.bench import tracking


@pytest.mark.parametrize("name", ["tuning", "held_out"])
def test_each_set_of_hand_counts_covers_the_video(name: str) -> None:
    hand = tracking.hand_counts()
    frames = sorted(getattr(hand, name))
    assert len(frames) >= 40 and hand.fps == 10
    assert frames[0] <= 20 and frames[-1] >= 760         # from start to end
    assert max(b - a for a, b in itertools.pairwise(frames)) <= 20


def test_the_held_out_frames_are_apart_from_the_tuning_frames() -> None:
    hand = tracking.hand_counts()
    # further than the flicker window, so no frame of one set is measured for the other
    assert all(abs(h - t) > 5 for h in hand.held_out for t in hand.tuning)


@pytest.fixture(scope="module")
def result() -> tracking.Result:
    measured = tracking.measure()
    assert measured.frames == 795
    for name, q in (("tuning", measured.tuning), ("held out", measured.held_out)):
        print(f"{name}: raw MAE {q.raw.mae:.3f}, flicker {q.raw.flicker:.3f}; "
              f"tracked MAE {q.tracked.mae:.3f}, flicker {q.tracked.flicker:.3f}; "
              f"ByteTrack's settings MAE {q.published.mae:.3f}, "
              f"flicker {q.published.flicker:.3f}")
    return measured


@pytest.mark.bench
def test_on_held_out_frames_tracked_counts_err_less_and_flicker_less_than_per_frame_counts(
        result: tracking.Result) -> None:
    held_out = result.held_out
    assert held_out.tracked.mae < held_out.raw.mae
    assert held_out.tracked.flicker < held_out.raw.flicker
    assert held_out.published.flicker < held_out.raw.flicker


@pytest.mark.bench
def test_on_the_tuning_frames_tracked_counts_err_less_and_flicker_less(
        result: tracking.Result) -> None:
    tuning = result.tuning
    assert tuning.tracked.mae < tuning.raw.mae
    assert tuning.tracked.flicker < tuning.raw.flicker
