"""Answers cut into sentences as they are generated: the cutter on its own, and Generate
with `sentences: true` on the real language model service, ended by a barge-in."""

from __future__ import annotations

from typing import Any

import pytest

from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, parse_pipeline
from oricf.gateway.methods.sentences import SentenceCutter, sentences
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Record
from tests.support.services import RunningService


def test_a_sentence_ends_at_its_mark_and_white_space() -> None:
    assert sentences("I see 4 people. Two walk left! Is that all? Yes; fine: done") == [
        "I see 4 people.", "Two walk left!", "Is that all?", "Yes;", "fine:", "done"]


@pytest.mark.parametrize("text", [
    "It is 3.5 meters away.", "Dr. Smith is here.", "Ask J. Smith now.",
    "Bring tools, e.g. a hammer.", "Costs approx. 4 euros."])
def test_numbers_and_abbreviations_end_nothing(text: str) -> None:
    assert sentences(text) == [text]


def test_pieces_make_the_same_sentences_as_the_whole_text() -> None:
    text = "I can see 4 people.\nTwo of them are 1.8 m tall. The rest? Unknown."
    cutter = SentenceCutter()
    got = [s for i in range(0, len(text), 3) for s in cutter.push(text[i:i + 3])]
    assert got + cutter.flush() == sentences(text) == [
        "I can see 4 people.", "Two of them are 1.8 m tall.", "The rest?", "Unknown."]


def test_a_sentence_is_held_until_what_follows_shows_it_ended() -> None:
    cutter = SentenceCutter()
    assert cutter.push("It is 3.") == []  # 3.5 or the end of the sentence?
    assert cutter.push("5 m away. Then") == ["It is 3.5 m away."]
    assert cutter.flush() == ["Then"]


def test_a_sentence_that_ends_beyond_doubt_goes_without_waiting_for_more() -> None:
    cutter = SentenceCutter()
    assert cutter.push("I see 3") == []
    assert cutter.push(" people.") == ["I see 3 people."]
    assert cutter.push(" Really?") == ["Really?"]
    for held in ("It is 3.", "Ask Dr.", "Bring tools, e.g.", "Meet me at 3:"):
        cutter = SentenceCutter()
        assert cutter.push(held) == [], held
        assert cutter.flush() == [held]


class Outputs(Emitter):
    """Collects what the routes send; `on` runs on each value (a barge-in in the test)."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, Any]] = []
        self.on: Any = None

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sent.append((output.source, value))
        if self.on is not None:
            self.on(output.source)

    def values(self, field: str) -> list[Any]:
        return [value for source, value in self.sent if source == field]


def asking(address: str) -> Any:
    return parse_pipeline({
        "endpoints": {"llm": {"address": address, "deadline_ms": 60000}},
        "routes": {"ask": {
            "input": {"text": "-"},
            "call": {"service": "llm", "method": "Generate", "prompt": "{text}",
                     "max_tokens": 48, "temperature": 0, "sentences": True},
            "outputs": [{"jsonl": "-", "from": "sentence"}, {"jsonl": "-", "from": "answer"}]}}},
        "test")


def test_each_sentence_goes_out_before_the_whole_answer_and_is_part_of_it(
        llm: RunningService) -> None:
    outputs = Outputs()
    pipeline = Pipeline(asking(llm.address), outputs)
    pipeline.start()
    pipeline.submit("ask", lambda: {"text": "Describe a busy street in two sentences."})
    assert pipeline.idle(120)
    pipeline.stop()
    said = outputs.values("sentence")
    assert said and [source for source, _ in outputs.sent][-1] == "answer"
    assert " ".join(said).split() == outputs.values("answer")[0].split()


def test_a_barge_in_ends_the_answer_and_drops_what_it_would_still_say(llm: RunningService) -> None:
    outputs = Outputs()
    pipeline = Pipeline(asking(llm.address), outputs)
    outputs.on = lambda source: pipeline.speaking.interrupt("test")
    pipeline.start()
    pipeline.submit("ask", lambda: {"text": "Describe a busy street in two sentences."})
    assert pipeline.idle(120)
    pipeline.stop()
    assert [source for source, _ in outputs.sent] == ["sentence"]  # no more, and no answer
    assert pipeline.routes["ask"].stats.skipped == 1
