"""Text arriving piece by piece (a language model's stream) cut into whole sentences, so that
each can be spoken while the rest is still being generated.

A sentence ends at `.`, `!`, `?`, `;` or `:` followed by white space, or at a line break. A
full stop after a number followed by a digit ("3.5") ends nothing, since no space follows
it; nor does one after a common abbreviation ("Dr. Smith", "e.g. this") or after a single
capital ("J. Smith").

The text so far need not wait for what follows when it already ends a sentence beyond
doubt: `!`, `?` or `;`, or `.` or `:` after a word of two letters or more that is no
abbreviation ("people."), but not after a number ("3." may become "3.5"). A language model
sends the mark some 60 ms before it ends its stream, and that is 60 ms sooner to speech.
"""

from __future__ import annotations

import re

ABBREVIATIONS = frozenset({
    "mr", "mrs", "ms", "dr", "prof", "st", "sr", "jr", "vs", "etc", "e.g", "i.e", "approx",
    "no", "fig", "mt", "ft", "inc", "ltd", "co",
})
_END = re.compile(r"([.!?;:]+)[\"')\]]*\s+|\n+")
_ENDS_NOW = re.compile(r"(?:[!?;]|(?<=[^\W\d_]{2})[.:])[\"')\]]*$")


class SentenceCutter:
    """push() pieces of text, get back the sentences they complete; flush() the rest."""

    def __init__(self) -> None:
        self._text = ""

    def push(self, piece: str) -> list[str]:
        self._text += piece
        sentences = []
        start = 0
        for match in _END.finditer(self._text):
            if match.group(1) == "." and _abbreviation(self._text[start:match.start()]):
                continue
            sentence = self._text[start:match.end()].strip()
            start = match.end()
            if sentence:
                sentences.append(sentence)
        rest = self._text[start:]
        if _ENDS_NOW.search(rest) and not _abbreviation(rest.rstrip("\"')]").rstrip(".:")):
            sentences.append(rest.strip())
            rest = ""
        self._text = rest
        return sentences

    def flush(self) -> list[str]:
        rest, self._text = self._text.strip(), ""
        return [rest] if rest else []


def _abbreviation(text: str) -> bool:
    """Whether the word before a full stop is an abbreviation (or a single capital)."""
    words = text.split()
    if not words:
        return False
    word = words[-1].lower().lstrip("(\"'")
    return word in ABBREVIATIONS or (len(word) == 1 and word.isalpha() and words[-1].isupper())


def sentences(text: str) -> list[str]:
    """The sentences of a whole text."""
    cutter = SentenceCutter()
    return cutter.push(text) + cutter.flush()
