"""Count quality on people counted by hand: the real detector service on every frame of
vtest.avi, counted per frame and through the `track` and `count_tracks` steps. Tracking
must both err less and flicker less than counting each frame on its own."""

from __future__ import annotations

import itertools

from oricf.bench import tracking


def test_the_hand_counts_cover_the_video() -> None:
    hand, fps = tracking.hand_counts()
    assert len(hand) >= 40 and fps == 10
    frames = sorted(hand)
    assert frames[0] <= 20 and frames[-1] >= 760         # from start to end
    assert max(b - a for a, b in itertools.pairwise(frames)) <= 20


def test_tracked_counts_err_less_and_flicker_less_than_per_frame_counts() -> None:
    result = tracking.measure()
    assert result.frames == 795
    print(f"raw: MAE {result.raw.mae:.3f}, flicker {result.raw.flicker:.3f}; "
          f"tracked: MAE {result.tracked.mae:.3f}, flicker {result.tracked.flicker:.3f}")
    assert result.tracked.mae < result.raw.mae
    assert result.tracked.flicker < result.raw.flicker
