"""`oricf bench voice`'s arithmetic: a question's stages from its clock marks, and the
median and p90 of each stage and of the total."""

from __future__ import annotations

import pytest

from oricf.bench.voice import STAGES, Turn, main, summary


def turn(ended: float, *marks: tuple[str, float]) -> Turn:
    result = Turn(ended=ended)
    result.marks.update(marks)
    return result


def test_the_stages_are_the_gaps_between_the_marks_in_order() -> None:
    done = turn(10.0, ("utterance", 10.5), ("transcript", 10.6), ("sentence", 11.0),
                ("audio", 11.1))
    stages = done.stages()
    assert stages is not None
    assert list(stages) == list(STAGES[:4])
    assert [round(v, 3) for v in stages.values()] == [0.5, 0.1, 0.4, 0.1]


def test_a_question_that_never_reached_audio_has_no_stages() -> None:
    assert turn(10.0, ("utterance", 10.5), ("transcript", 10.6)).stages() is None


def test_medians_and_p90_over_the_answered_questions() -> None:
    turns = [turn(0.0, ("utterance", 0.4), ("transcript", 0.5), ("sentence", 0.5 + s),
                  ("audio", 0.6 + s)) for s in (0.1, 0.2, 0.3, 0.4, 0.5)]
    turns.append(turn(0.0, ("utterance", 0.4)))  # unanswered: left out
    table = summary(turns)
    assert table["LLM 1st sentence"][0] == pytest.approx(300)
    # p90 is a value measured (oricf.stats.p90): of five, the largest
    assert table["LLM 1st sentence"][1] == pytest.approx(500)
    assert table["total"][0] == pytest.approx(900)
    assert "device" not in table


def test_a_question_cut_in_two_is_left_out_of_the_timings() -> None:
    split = turn(10.0, ("utterance", 9.8), ("transcript", 9.9), ("sentence", 10.2),
                 ("audio", 10.3))
    split.utterances = 2
    assert split.stages() is None
    whole = turn(10.0, ("utterance", 10.5), ("transcript", 10.6), ("sentence", 11.0),
                 ("audio", 11.1))
    whole.utterances = 1
    assert whole.stages() is not None


@pytest.mark.parametrize("silences", ["abc", "400,16"])
def test_end_silences_that_cannot_be_used_are_refused_before_anything_starts(
        silences: str) -> None:
    with pytest.raises(SystemExit, match="--min-silence-ms"):
        main(["--min-silence-ms", silences])
