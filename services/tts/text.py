"""What text the speech service accepts, and how it becomes speakable sentences.

The rule (docs/speech-out.md), checked before anything is synthesized:
- the text is not empty (after white space) and has at most `text.max_chars` characters;
- no control characters other than tab, line feed and carriage return (refused);
- no markup: `<` followed by a letter, `/`, `!` or `?` (an SSML or HTML tag), and no `[[` or
  `]]` (espeak-ng's inline phoneme brackets) are refused, since neither engine may be steered
  by text from a language model or a user;
- invisible format characters (zero-width spaces and joiners, bidirectional marks) are removed.

Normalisation then writes out what a voice would misread: numbers ("4", "12.5", "-3",
"1,000", years, ordinals such as "21st"), times ("10:30"), percentages, dollars, units after
a number ("2.5 m"), common abbreviations ("Dr.", "e.g.") and a few symbols. The text written
out may be at most `text.max_spoken_chars` long. Sentences end at
".", "!" or "?" followed by a space, or at a line break; one longer than
`text.max_sentence_chars` is cut at a comma or a space, so the first audio of a stream never
waits for a run-on sentence.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Callable

from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.errors import InvalidInput
from oricf.services.tts import numbers

# Said in full wherever they appear (case as written, the dot included).
ABBREVIATIONS = {
    "Dr.": "Doctor", "Mr.": "Mister", "Mrs.": "Missus", "Ms.": "Miz", "St.": "Saint",
    "Prof.": "Professor", "vs.": "versus", "etc.": "et cetera", "e.g.": "for example",
    "i.e.": "that is", "approx.": "approximately", "No.": "number", "min.": "minutes",
    "Jan.": "January", "Feb.": "February", "Aug.": "August", "Sept.": "September",
    "Oct.": "October", "Nov.": "November", "Dec.": "December",
}
# Units written after a number: (singular, plural), spelt as the en-US voices say them.
UNITS = {
    "mm": ("millimeter", "millimeters"), "cm": ("centimeter", "centimeters"),
    "m": ("meter", "meters"), "km": ("kilometer", "kilometers"), "g": ("gram", "grams"),
    "kg": ("kilogram", "kilograms"), "ms": ("millisecond", "milliseconds"),
    "s": ("second", "seconds"), "h": ("hour", "hours"), "min": ("minute", "minutes"),
    "km/h": ("kilometer per hour", "kilometers per hour"),
    "m/s": ("meter per second", "meters per second"), "°C": ("degree Celsius", "degrees Celsius"),
    "°F": ("degree Fahrenheit", "degrees Fahrenheit"), "°": ("degree", "degrees"),
    "V": ("volt", "volts"), "W": ("watt", "watts"), "Hz": ("hertz", "hertz"),
}
SYMBOLS = {"&": " and ", "+": " plus ", "=": " equals ", "<": " less than ",
           ">": " greater than ", "@": " at ", "#": " number ", "~": " about ",
           "*": " ", "_": " ", "|": " ", "\\": " ", "/": " slash ", "{": " ", "}": " "}

ALLOWED_CONTROLS = "\t\n\r"
MARKUP = re.compile(r"<\s*[A-Za-z/!?]|\[\[|\]\]")
NUMBER = r"[-+]?(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?"
UNIT_NAMES = "|".join(re.escape(u) for u in sorted(UNITS, key=len, reverse=True))
UNIT_AFTER_NUMBER = re.compile(rf"(?<![\w.])({NUMBER})\s?({UNIT_NAMES})(?![\w/])")
ORDINAL = re.compile(r"\b(\d+)(st|nd|rd|th)\b", re.IGNORECASE)
TIME = re.compile(r"\b([01]?\d|2[0-3]):([0-5]\d)\b")
PERCENT = re.compile(rf"({NUMBER})\s?%")
DOLLARS = re.compile(rf"\$({NUMBER})")
YEAR = re.compile(r"(?<![\d.,-])(1[1-9]\d\d)(?![\d.,]\d)")
PLAIN_NUMBER = re.compile(rf"(?<![\w.]){NUMBER}(?!\w)")
SENTENCE_END = re.compile(r"(?<=[.!?])[\"')\]]*\s+|\s*\n+\s*")
SPACES = re.compile(r"\s+")
SPACE_BEFORE_PUNCTUATION = re.compile(r"\s+(?=[.,!?;:])")


class TextSettings(Schema):
    """`text:` of configs/services/tts.yaml."""

    max_chars: int = Field(2000, ge=1, le=100_000,
                           description="longest text one request may carry (characters)")
    max_spoken_chars: int = Field(
        4000, ge=1, le=400_000,
        description="longest the text may be once written out for speech (numbers, units, "
                    "abbreviations and symbols in words): \"1\" + \",000\" * 400 is 1,601 "
                    "characters that read as 6,000")
    max_sentence_chars: int = Field(
        200, ge=20, le=10_000, description="a longer sentence is cut at a comma or a space")
    abbreviations: dict[str, str] = Field(
        default_factory=dict, description="said in full, beside the built-in ones")

    @model_validator(mode="after")
    def _spoken_fits(self) -> TextSettings:
        if self.max_spoken_chars < self.max_chars:
            raise ValueError(f"max_spoken_chars ({self.max_spoken_chars}) must be at least "
                             f"max_chars ({self.max_chars}): text is never shorter written out")
        return self


def check(text: str, max_chars: int) -> str:
    """The text if it follows the rule (module docstring), format characters removed."""
    if len(text) > max_chars:
        raise InvalidInput(f"text: {len(text):,} characters, more than this service's limit "
                           f"of {max_chars:,} (text.max_chars)")
    for i, char in enumerate(text):
        if unicodedata.category(char) == "Cc" and char not in ALLOWED_CONTROLS:
            raise InvalidInput(f"text: control character U+{ord(char):04X} at position {i}; "
                               f"send plain text (tab and line breaks are allowed)")
    markup = MARKUP.search(text)
    if markup is not None:
        raise InvalidInput(f"text: markup at position {markup.start()} "
                           f"({markup.group()!r}); send plain text, not SSML, HTML or "
                           f"phoneme brackets")
    text = "".join(c for c in text if unicodedata.category(c) != "Cf")
    if not text.strip():
        raise InvalidInput("text: empty; send the words to say")
    return text


def check_spoken(normalised: str, max_spoken_chars: int) -> str:
    """The normalised text if it is within the limit: written-out numbers can make text many
    times longer, and what a voice must say costs in proportion."""
    if len(normalised) > max_spoken_chars:
        raise InvalidInput(f"text: {len(normalised):,} characters once numbers, units and "
                           f"abbreviations are written out for speech, more than this "
                           f"service's limit of {max_spoken_chars:,} (text.max_spoken_chars)")
    return normalised


def _sub(pattern: re.Pattern[str], say: Callable[[re.Match[str]], str], text: str) -> str:
    return pattern.sub(lambda m: f" {say(m)} ", text)


def _unit(match: re.Match[str]) -> str:
    value, unit = match.group(1), match.group(2)
    singular, plural = UNITS[unit]
    return f"{numbers.decimal(value)} {singular if value.lstrip('+') == '1' else plural}"


def _ordinal(match: re.Match[str]) -> str:
    digits = match.group(1)
    if len(digits) > numbers.MAX_CARDINAL_DIGITS:  # a serial number: never made an int
        return numbers.digits(digits)
    return numbers.ordinal(int(digits))


def _time(match: re.Match[str]) -> str:
    hours, minutes = int(match.group(1)), int(match.group(2))
    if minutes == 0:
        return f"{numbers.cardinal(hours)} o'clock"
    tail = f"oh {numbers.cardinal(minutes)}" if minutes < 10 else numbers.cardinal(minutes)
    return f"{numbers.cardinal(hours)} {tail}"


def say_numbers(text: str) -> str:
    """Every number, unit, time, percentage and dollar amount written out in words."""
    text = _sub(TIME, _time, text)
    text = _sub(ORDINAL, _ordinal, text)
    text = _sub(DOLLARS, lambda m: numbers.decimal(m.group(1)) + (
        " dollar" if m.group(1) == "1" else " dollars"), text)
    text = _sub(PERCENT, lambda m: f"{numbers.decimal(m.group(1))} percent", text)
    text = _sub(UNIT_AFTER_NUMBER, _unit, text)
    text = _sub(YEAR, lambda m: numbers.year(int(m.group(1))), text)
    return _sub(PLAIN_NUMBER, lambda m: numbers.decimal(m.group()), text)


def normalise(text: str, abbreviations: dict[str, str] | None = None) -> str:
    """Checked text as a voice should read it: abbreviations, numbers and symbols in words,
    white space collapsed within lines (line breaks stay: they end sentences)."""
    table = {**ABBREVIATIONS, **(abbreviations or {})}
    for short in sorted(table, key=len, reverse=True):
        text = re.sub(rf"(?<!\w){re.escape(short)}(?!\w)", table[short], text)
    text = say_numbers(text)
    text = "".join(SYMBOLS.get(c, c) for c in text)
    lines = (SPACE_BEFORE_PUNCTUATION.sub("", SPACES.sub(" ", line)).strip()
             for line in text.splitlines())
    return "\n".join(line for line in lines if line)


def cut(sentence: str, limit: int) -> list[str]:
    """A sentence in pieces of at most `limit` characters, cut after a comma or at a space."""
    pieces = []
    while len(sentence) > limit:
        window = sentence[:limit + 1]  # a space just after the limit is a fine cut too
        comma, space = window.rfind(", "), window.rfind(" ")
        at = comma + 1 if comma > 0 else space if space > 0 else limit  # else mid-word
        pieces.append(sentence[:at].strip())
        sentence = sentence[at:].strip()
    return [*pieces, sentence] if sentence else pieces


def sentences(text: str, max_chars: int) -> list[str]:
    """Normalised text in sentences, each at most max_chars long; only those with a letter
    or digit in them (a stray "..." says nothing)."""
    out = []
    for sentence in SENTENCE_END.split(text):
        if any(c.isalnum() for c in sentence):
            out.extend(cut(sentence.strip(), max_chars))
    return out
