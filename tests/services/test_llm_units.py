"""The LLM service's model-free parts: stop sequences, the generation gate, answer grading."""

import threading
import time

import pytest

from oricf.bench.llm import is_right, questions, stated_counts
from oricf.errors import Cancelled, NotReady, Overloaded
from oricf.services.llm.decode import StopScanner
from oricf.services.llm.gate import GenerationGate


def scan(stops: list[str], pieces: list[str]) -> tuple[str, bool]:
    scanner = StopScanner(stops)
    out = ""
    for piece in pieces:
        text, stopped = scanner.feed(piece)
        out += text
        if stopped:
            return out, True
    return out + scanner.flush(), False


def test_stop_sequence_split_across_tokens() -> None:
    assert scan(["<|im_end|>"], ["I see", " 3<|im", "_end|>more"]) == ("I see 3", True)


def test_partial_stop_is_released_when_it_turns_out_not_to_be_one() -> None:
    scanner = StopScanner(["END"])
    assert scanner.feed("I see EN") == ("I see ", False)
    assert scanner.feed("TRY") == ("ENTRY", False)


def test_earliest_stop_wins_and_no_stops_pass_everything() -> None:
    assert scan(["\n", "people"], ["3 people\nmore"]) == ("3 ", True)
    assert scan([], ["a\n", "b"]) == ("a\nb", False)


def never_cancelled() -> None:
    pass


def test_gate_one_at_a_time_in_arrival_order() -> None:
    gate = GenerationGate(max_waiting=3, wait_timeout_s=5)
    order: list[int] = []

    def worker(i: int) -> None:
        with gate.turn(never_cancelled):
            order.append(i)
            time.sleep(0.05)

    with gate.turn(never_cancelled):
        threads = []
        for i in range(3):
            threads.append(threading.Thread(target=worker, args=(i,)))
            threads[-1].start()
            while gate.waiting < i + 1:
                time.sleep(0.005)
    for thread in threads:
        thread.join(timeout=5)
    assert order == [0, 1, 2]
    assert not gate.busy and gate.waiting == 0


def test_gate_refuses_beyond_its_queue() -> None:
    gate = GenerationGate(max_waiting=0, wait_timeout_s=5)
    with gate.turn(never_cancelled), pytest.raises(Overloaded, match="queue limit 0"), \
            gate.turn(never_cancelled):
        pass
    with gate.turn(never_cancelled) as waited:  # free again
        assert waited < 0.1


def test_gate_wait_timeout_and_cancelled_waiter() -> None:
    gate = GenerationGate(max_waiting=2, wait_timeout_s=0.2)
    errors: list[Exception] = []

    def wait(check: object) -> None:
        try:
            with gate.turn(check):  # type: ignore[arg-type]
                pass
        except Exception as exc:
            errors.append(exc)

    def cancelled() -> None:
        raise Cancelled("gone")

    with gate.turn(never_cancelled):
        for check in (never_cancelled, cancelled):
            thread = threading.Thread(target=wait, args=(check,))
            thread.start()
            thread.join(timeout=5)
    assert isinstance(errors[0], Overloaded) and "queue wait timeout" in str(errors[0])
    assert isinstance(errors[1], Cancelled)
    assert gate.waiting == 0 and not gate.busy


@pytest.mark.parametrize(("answer", "counts"), [
    ("I see 3 people.", {3}),
    ("Yes, I see three people.", {3}),
    ("No, I see no one.", {0}),
    ("Nobody is here.", {0}),
    ("No, I see 1 person.", {1}),
    ("I see 13 people.", {13}),
    ("I see someone, maybe 2 or 4.", {2, 4}),
    ("I don't know how many people are here.", set()),
    ("Yes, I am alone.", set()),
])
def test_bench_reads_the_stated_counts(answer: str, counts: set[int]) -> None:
    assert stated_counts(answer) == counts


def test_bench_grading_and_questions() -> None:
    assert is_right("I see 3 people.", 3) and not is_right("I see 3 people, not 13.", 3)
    asked = questions(64)
    assert len(set(asked)) == 64 and {c for _, c in asked} == set(range(16))
    assert len({q for q, _ in asked}) >= 12


def test_gate_close_waits_for_the_running_turn_then_refuses() -> None:
    gate = GenerationGate(max_waiting=1, wait_timeout_s=5)
    released = threading.Event()

    def hold() -> None:
        with gate.turn(never_cancelled):
            released.wait(5)

    holder = threading.Thread(target=hold)
    holder.start()
    while not gate.busy:
        time.sleep(0.005)
    assert gate.close(timeout_s=0.05) is False  # still running
    released.set()
    assert gate.close(timeout_s=5) is True
    holder.join(timeout=5)
    with pytest.raises(NotReady, match="shutting down"), gate.turn(never_cancelled):
        pass
