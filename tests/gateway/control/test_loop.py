"""The control loop's tick: asked before acting, so an onboard answer is used at once; the
last action held, then the safe action, when nothing is queued; requests that stay
unanswered past the deadline asked again; answers that come late or twice, or that answer
what was never asked, move nothing; nothing is played beyond the policy's horizon."""

from __future__ import annotations

import numpy as np
import pytest

from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.control.queue import ActionQueue, BadChunk, Origin

SAFE = np.array([0.0, 0.0])


def chunk(first: float, n: int) -> np.ndarray:
    return np.repeat(np.arange(first, first + n, dtype=np.float64)[:, None], 2, axis=1)


def loop(horizon: int = 64, **settings: object) -> ControlLoop:
    options = {"request_at": 2, "deadline": 5} | settings
    return ControlLoop(ActionQueue(2, horizon=horizon), SAFE,
                       **options)  # type: ignore[arg-type]


def test_an_answer_before_the_action_is_used_on_the_same_tick() -> None:
    control = loop()
    request = control.ask(0, np.ones(3))
    assert request is not None and request.step == 0
    control.deliver(chunk(100, 4), start_step=0, origin=Origin(0), now=-1)
    tick = control.act(0)
    assert tick.action[0] == 100 and not tick.safe and tick.origin == Origin(0)


def test_the_next_chunk_is_asked_for_when_request_at_actions_are_left() -> None:
    control = loop(request_at=2)
    assert control.ask(0, np.ones(3)) is not None
    control.deliver(chunk(0, 4), 0, Origin(0), now=-1)
    asked = []
    for step in range(4):
        asked.append(control.ask(step, np.ones(3)) is not None)
        control.act(step)
    # Queued from step 0: 4, 3, then 2 (asked), then pending until answered.
    assert asked == [False, False, True, False]
    assert control.counts.requests == 2


def test_a_dry_queue_holds_the_last_action_then_sends_the_safe_one() -> None:
    control = loop(hold_steps=2)
    control.ask(0, np.ones(3))
    control.deliver(chunk(7, 1), 0, Origin(0), now=-1)
    ticks = [control.act(step) for step in range(4)]
    assert [t.action[0] for t in ticks] == [7, 7, 7, 0]
    assert [t.safe for t in ticks] == [False, False, False, True]
    assert (control.counts.held_ticks, control.counts.safe_ticks) == (2, 1)


def test_a_request_past_its_deadline_is_asked_again_and_its_late_answer_still_counts() -> None:
    control = loop(deadline=3, request_at=0)
    assert control.ask(0, np.ones(3)) is not None
    assert all(control.ask(step, np.ones(3)) is None for step in range(1, 4))
    assert control.ask(4, np.ones(3)) is not None  # the first is given up
    assert control.counts.expired == 1
    # The first answer arrives after all: its actions for passed steps are skipped.
    assert control.deliver(chunk(0, 8), 0, Origin(0), now=5) == 2
    assert control.act(6).action[0] == 6


def test_an_answer_to_an_older_or_answered_observation_is_refused() -> None:
    control = loop(max_in_flight=3, request_at=10)
    for step in range(3):
        control.ask(step, np.ones(3))
    assert control.deliver(chunk(0, 8), 2, Origin(2), now=2) > 0
    assert control.deliver(chunk(0, 8), 1, Origin(1), now=2) == 0     # older
    assert control.deliver(chunk(0, 8), 2, Origin(2), now=2) == 0     # twice
    assert control.counts.refused_chunks == 2


def test_a_failed_call_lets_the_next_tick_ask_again() -> None:
    control = loop(request_at=0)
    assert control.ask(0, np.ones(3)) is not None
    assert control.ask(1, np.ones(3)) is None
    control.failed(0)
    assert control.ask(2, np.ones(3)) is not None


def test_a_malformed_chunk_is_refused_and_the_loop_asks_again() -> None:
    control = loop(request_at=0)
    control.ask(0, np.ones(3))
    with pytest.raises(BadChunk):
        control.deliver(np.array([[np.nan, 0.0]]), 0, Origin(0), now=-1)
    assert control.act(0).safe
    assert control.ask(1, np.ones(3)) is not None


def test_committed_actions_go_with_the_request_for_real_time_chunking() -> None:
    control = loop(request_at=3, send_committed=True)
    control.ask(0, np.ones(3))
    control.deliver(chunk(0, 4), 0, Origin(0), now=-1)
    control.act(0)
    request = control.ask(1, np.ones(3))
    assert request is not None and request.committed is not None
    start, rows = request.committed
    assert start == 1 and rows[:, 0].tolist() == [1, 2, 3]


def test_stop_drops_what_is_queued() -> None:
    control = loop()
    control.ask(0, np.ones(3))
    control.deliver(chunk(5, 4), 0, Origin(0), now=-1)
    control.stop()
    assert control.act(0).safe


def test_a_restart_drops_what_was_queued_and_refuses_answers_from_before_it() -> None:
    control = loop(hold_steps=3)
    control.ask(0, np.ones(3))
    control.deliver(chunk(5, 8), 0, Origin(0), now=-1)
    assert control.act(0).action[0] == 5
    assert control.ask(1, np.ones(3)) is None  # enough queued: nothing asked
    control.ask(2, np.ones(3))                 # asked for the observation of step 2
    control.restart()
    tick = control.act(4)
    assert tick.safe  # neither the queued action for step 4 nor the last one, held
    # The answer to step 2's observation comes after the restart: refused, nothing queued.
    assert control.deliver(chunk(50, 8), 2, Origin(2), now=4) == 0
    assert control.counts.refused_chunks == 1 and control.counts.restarts == 1
    # A request for the observation after it is answered and played.
    assert control.ask(5, np.ones(3)) is not None
    control.deliver(chunk(70, 4), 5, Origin(5), now=4)
    assert control.act(5).action[0] == 70


@pytest.mark.parametrize("lie", [10**6, 2**40])
def test_an_answer_for_a_step_never_asked_is_refused_and_the_next_is_taken(lie: int) -> None:
    """An edge that names a step far ahead of any it was asked for poisons nothing: the
    answers after it, to the steps the loop asked, are taken."""
    control = loop(request_at=0)
    assert control.ask(0, np.ones(3)) is not None
    assert control.deliver(chunk(9, 4), 0, Origin(lie), now=-1) == 0
    assert control.counts.refused_chunks == 1 and control.counts.answers == 0
    assert control.deliver(chunk(20, 4), 0, Origin(0), now=-1) == 4  # what was asked
    assert control.act(0).action[0] == 20
    for step in range(1, 4):
        control.act(step)
    assert control.ask(4, np.ones(3)) is not None  # once the queue is dry
    assert control.deliver(chunk(30, 4), 4, Origin(4), now=3) == 4
    assert control.act(4).action[0] == 30 and control.counts.answers == 2


def test_an_answer_refused_by_its_caller_lets_the_next_tick_ask_again() -> None:
    control = loop(request_at=0)
    control.ask(0, np.ones(3))
    control.refuse(0)  # e.g. it said it answers another observation
    assert control.counts.refused_chunks == 1
    assert control.ask(1, np.ones(3)) is not None  # not after the deadline: at once
    assert control.deliver(chunk(9, 4), 0, Origin(0), now=0) == 0  # nor taken after all


def test_a_chunk_planted_beyond_the_horizon_is_refused_and_the_safe_action_follows() -> None:
    """An edge answers once with actions 150 steps ahead and then goes silent: at their step
    the loop holds the last action, then sends the safe one, not the planted action."""
    control = loop(horizon=16, request_at=0, hold_steps=2)
    control.ask(0, np.ones(3))
    control.deliver(chunk(7, 4), 0, Origin(0), now=-1)
    ticks = [control.act(step) for step in range(4)]
    control.ask(4, np.ones(3))
    with pytest.raises(BadChunk, match="beyond the horizon of 16 steps"):
        control.deliver(chunk(99, 14), 154, Origin(4), now=3)
    ticks += [control.act(step) for step in range(4, 170)]
    assert not any(tick.action[0] >= 99 for tick in ticks)
    assert [tick.action[0] for tick in ticks[:7]] == [7, 8, 9, 10, 10, 10, 0]
    assert all(tick.safe for tick in ticks[6:])
    assert control.counts.refused_chunks == 1


def test_the_actions_of_a_chunk_beyond_the_horizon_are_dropped() -> None:
    control = loop(horizon=5, request_at=0)
    control.ask(2, np.ones(3))
    assert control.deliver(chunk(0, 10), 2, Origin(2), now=1) == 6  # steps 2 to 7
    assert control.queue.counts.ahead_actions == 4
    assert [control.act(step).action[0] for step in range(2, 10)] == [0, 1, 2, 3, 4, 5, 0, 0]
