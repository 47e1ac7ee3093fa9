"""The speech service's text rule and normalisation: what is refused and why, numbers, units
and abbreviations in words, and sentences for SynthesizeStream."""

from __future__ import annotations

import pytest

from oricf.errors import InvalidInput
from oricf.services.tts import numbers
from oricf.services.tts.text import check, check_spoken, normalise, sentences


@pytest.mark.parametrize(("value", "words"), [
    (0, "zero"), (4, "four"), (13, "thirteen"), (21, "twenty-one"), (100, "one hundred"),
    (101, "one hundred one"), (1200, "one thousand two hundred"),
    (12_345, "twelve thousand three hundred forty-five"), (1_000_000, "one million"),
    (-3, "minus three"), (10**15, "one zero zero zero zero zero zero zero zero zero zero zero "
                                  "zero zero zero zero"),
])
def test_cardinals(value: int, words: str) -> None:
    assert numbers.cardinal(value) == words


@pytest.mark.parametrize(("value", "words"), [
    (1, "first"), (2, "second"), (3, "third"), (5, "fifth"), (8, "eighth"), (9, "ninth"),
    (12, "twelfth"), (20, "twentieth"), (21, "twenty-first"), (100, "one hundredth"),
    (103, "one hundred third"),
])
def test_ordinals(value: int, words: str) -> None:
    assert numbers.ordinal(value) == words


@pytest.mark.parametrize(("text", "said"), [
    ("I can see 4 people.", "I can see four people."),
    ("It is 12.5 m away.", "It is twelve point five meters away."),
    ("1 m", "one meter"),
    ("It is -3 °C outside.", "It is minus three degrees Celsius outside."),
    ("There are 1,000 boxes.", "There are one thousand boxes."),
    ("The battery is at 80%.", "The battery is at eighty percent."),
    ("It costs $5.", "It costs five dollars."),
    ("Built in 1984, rebuilt in 2024.",
     "Built in nineteen eighty-four, rebuilt in two thousand twenty-four."),
    ("My 1st and 22nd tasks.", "My first and twenty-second tasks."),
    ("At 10:30 or 9:05 or 7:00.", "At ten thirty or nine oh five or seven o'clock."),
    ("Dr. Smith, e.g. at St. Mary's.", "Doctor Smith, for example at Saint Mary's."),
    ("cats & dogs", "cats and dogs"),
    ("3 < 4", "three less than four"),
    ("Pi is 3.14", "Pi is three point one four"),
])
def test_normalisation_says_numbers_units_and_abbreviations(text: str, said: str) -> None:
    assert normalise(check(text, 2000)) == said


def test_abbreviations_from_the_yaml_join_the_built_in_ones() -> None:
    assert normalise("ORICF at 2 Hz", {"ORICF": "oh rick f"}) == "oh rick f at two hertz"


def test_sentences_end_at_marks_and_line_breaks() -> None:
    text = normalise("Hello there. I see 2 people! Shall I follow them?\nYes sir")
    assert sentences(text, 300) == ["Hello there.", "I see two people!",
                                    "Shall I follow them?", "Yes sir"]


def test_a_decimal_point_or_an_abbreviation_does_not_end_a_sentence() -> None:
    text = normalise("It is 2.5 m away, e.g. near the door. Go there.")
    assert sentences(text, 300) == ["It is two point five meters away, for example near "
                                    "the door.", "Go there."]


def test_a_long_sentence_is_cut_at_a_comma_or_a_space() -> None:
    text = "one, " * 30 + "word " * 100
    pieces = sentences(normalise(text), 120)
    assert all(len(p) <= 120 for p in pieces) and len(pieces) >= 5
    assert " ".join(pieces).split() == normalise(text).split()
    assert pieces[0].endswith(",")


def test_a_sentence_without_spaces_is_cut_at_the_limit() -> None:
    assert [len(p) for p in sentences("x" * 700, 300)] == [300, 300, 100]
    assert [len(p) for p in sentences("x" * 250 + " " + "y" * 400, 300)] == [250, 300, 100]


def test_stray_punctuation_says_nothing() -> None:
    assert sentences(normalise("... !? -"), 300) == []


def test_format_characters_are_removed() -> None:
    assert check("he\u200bllo\u202e", 100) == "hello"


@pytest.mark.parametrize(("text", "said"), [
    ("", "empty"), (" \n\t", "empty"), ("a\x00b", "U+0000"), ("a\x1bb", "U+001B"),
    ("a\x7fb", "U+007F"), ("<speak>hi</speak>", "markup"), ("hi </voice>", "markup"),
    ("<!-- x -->", "markup"), ("<?xml?>", "markup"), ("say [[h@loU]]", "markup"),
    ("x" * 101, "limit of 100"),
])
def test_the_rule_refuses_with_a_reason(text: str, said: str) -> None:
    with pytest.raises(InvalidInput) as refused:
        check(text, 100)
    assert said in str(refused.value)


def test_tabs_and_line_breaks_are_allowed() -> None:
    assert check("one\ttwo\r\nthree", 100) == "one\ttwo\r\nthree"


def test_text_that_writes_out_too_long_is_refused() -> None:
    said = normalise("1" + ",000" * 400)  # digit by digit: "one zero zero ..."
    assert len(said) == 6003
    with pytest.raises(InvalidInput) as refused:
        check_spoken(said, 4000)
    assert str(refused.value) == ("text: 6,003 characters once numbers, units and abbreviations "
                                  "are written out for speech, more than this service's limit "
                                  "of 4,000 (text.max_spoken_chars)")
    assert check_spoken(said, 6003) == said


@pytest.mark.parametrize("text", ["7" * 5000, "7" * 5000 + "th", "-" + "7" * 5000 + ".5"])
def test_a_number_of_thousands_of_digits_is_read_digit_by_digit(text: str) -> None:
    # Python refuses to make an int of more than 4300 digits: such a number never becomes one.
    said = normalise(text)
    assert said.count("seven") == 5000 and said.endswith(("seven", "five"))
