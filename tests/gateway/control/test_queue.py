"""The action queue: chunks placed by the step each action is for, late actions skipped or
the chunk shifted, overlaps merged, and the counts the bench reports."""

from __future__ import annotations

import numpy as np
import pytest

from oricf.gateway.control.queue import ActionQueue, BadChunk, Origin


def chunk(first: float, n: int, dim: int = 2) -> np.ndarray:
    """n actions whose values say which they are: first, first + 1, ... in every column."""
    return np.repeat(np.arange(first, first + n, dtype=np.float64)[:, None], dim, axis=1)


def test_a_late_chunk_is_followed_on_time_when_late_actions_are_skipped() -> None:
    queue = ActionQueue(2, late="skip")
    # Its first action is for step 11 and it arrives at step 13: its actions for 11-13 passed.
    assert queue.put(chunk(11, 8), start_step=11, now=13) == 5
    assert queue.counts.late_actions == 3
    assert queue.remaining(14) == 5
    assert [queue.take(step)[0] for step in range(14, 19)] == [14, 15, 16, 17, 18]
    assert queue.take(19) is None
    assert (queue.counts.ticks, queue.counts.empty_ticks) == (6, 1)


def test_a_shifted_chunk_starts_at_the_tick_after_it_arrives() -> None:
    queue = ActionQueue(2, late="shift")
    assert queue.put(chunk(0, 4), start_step=11, now=13) == 4
    assert [queue.take(step)[0] for step in range(14, 18)] == [0, 1, 2, 3]
    assert queue.counts.late_actions == 0


def test_a_chunk_all_late_is_counted_stale_and_queues_nothing() -> None:
    queue = ActionQueue(2)
    assert queue.put(chunk(0, 3), start_step=11, now=20) == 0
    assert (queue.counts.stale_chunks, queue.counts.late_actions) == (1, 3)
    assert queue.take(21) is None


@pytest.mark.parametrize(("merge", "expected"), [
    ("latest", 100.0),
    ("weighted", 0.3 * 1 + 0.7 * 100),
    ("ensemble", (1 + np.exp(-0.01) * 100) / (1 + np.exp(-0.01))),
])
def test_overlapping_chunks_are_merged(merge: str, expected: float) -> None:
    queue = ActionQueue(1, merge=merge)  # type: ignore[arg-type]
    queue.put(np.ones((4, 1)), start_step=1, now=0)          # steps 1-4
    queue.put(np.full((4, 1), 100.0), start_step=3, now=2)    # steps 3-6
    assert queue.take(3)[0] == pytest.approx(expected)
    assert queue.take(5)[0] == 100.0  # one chunk alone: as it is


def test_steps_passed_are_forgotten_and_switches_measure_the_jump() -> None:
    queue = ActionQueue(1)
    queue.put(chunk(1, 4, dim=1), start_step=1, now=0)         # 1, 2, 3, 4
    assert queue.take(1)[0] == 1 and queue.take(2)[0] == 2
    queue.put(chunk(10, 4, dim=1), start_step=3, now=2)        # 3 -> 10, ...
    assert queue.take(3)[0] == 10
    assert (queue.counts.switches, list(queue.counts.jumps)) == (1, [8.0])
    assert queue.take(5)[0] == 12  # step 4's action went unplayed: gone
    assert queue.take(4) is None


def test_the_committed_actions_are_what_will_be_played() -> None:
    queue = ActionQueue(1, merge="weighted")
    queue.put(np.ones((3, 1)), start_step=1, now=0)
    queue.put(np.full((3, 1), 2.0), start_step=2, now=1)
    start, rows = queue.committed(2)
    assert start == 2 and rows[:, 0].tolist() == pytest.approx([1.7, 1.7, 2.0])
    assert queue.committed(9)[1].shape == (0, 1)


@pytest.mark.parametrize("bad", [np.ones((3, 3)), np.ones((0, 2)), np.ones(2),
                                 np.array([[1.0, np.nan]]), np.array([[np.inf, 0.0]])])
def test_bad_chunks_are_refused_and_leave_the_queue_as_it_was(bad: np.ndarray) -> None:
    queue = ActionQueue(2)
    queue.put(chunk(1, 2), start_step=1, now=0)
    with pytest.raises(BadChunk):
        queue.put(bad, start_step=1, now=0)
    assert queue.remaining(1) == 2 and queue.counts.chunks == 1



@pytest.mark.parametrize("late", ["skip", "shift"])
def test_no_action_is_queued_beyond_the_horizon_of_its_observation(late: str) -> None:
    """An action for a step more than `horizon` steps after the observation it answers, where
    `late` places it, is dropped; a chunk whose first action is there is refused."""
    queue = ActionQueue(2, late=late, horizon=10)  # type: ignore[arg-type]
    # Observed at step 10, arriving at step 14, placed from step 15: steps 15 to 20 are
    # within 10 steps of it.
    assert queue.put(chunk(0, 8), start_step=15, now=14, origin=Origin(10)) == 6
    assert queue.counts.ahead_actions == 2
    assert [queue.take(step)[0] for step in range(15, 21)] == [0, 1, 2, 3, 4, 5]
    assert queue.take(21) is None


def test_a_chunk_that_starts_beyond_the_horizon_is_refused() -> None:
    queue = ActionQueue(2, horizon=10)
    with pytest.raises(BadChunk, match="150 steps after the observation it answers"):
        queue.put(chunk(0, 14), start_step=160, now=12, origin=Origin(10))
    assert queue.counts.chunks == 0 and queue.remaining(13) == 0
