"""Numbers as English words, for speech: cardinals, ordinals, decimals and years.

Written here rather than taken from num2words (LGPL-2.1): ORICF needs a few dozen lines of
English only, and keeps its dependencies Apache-2.0 compatible without a second thought.
"""

from __future__ import annotations

ONES = ["zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
        "eleven", "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen",
        "eighteen", "nineteen"]
TENS = ["_", "_", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety"]
SCALES = ((10**12, "trillion"), (10**9, "billion"), (10**6, "million"), (1000, "thousand"))
# An ordinal's last word, where it is not the cardinal plus "th".
ORDINAL_ENDINGS = {"one": "first", "two": "second", "three": "third", "five": "fifth",
                   "eight": "eighth", "nine": "ninth", "twelve": "twelfth"}
# Beyond this a number is read digit by digit (a serial number, not a quantity).
MAX_CARDINAL = 10**15 - 1
MAX_CARDINAL_DIGITS = len(str(MAX_CARDINAL))


def _below_hundred(n: int) -> str:
    if n < 20:
        return ONES[n]
    tens, ones = divmod(n, 10)
    return TENS[tens] + (f"-{ONES[ones]}" if ones else "")


def _below_thousand(n: int) -> str:
    hundreds, rest = divmod(n, 100)
    words = [f"{ONES[hundreds]} hundred"] if hundreds else []
    if rest:
        words.append(_below_hundred(rest))
    return " ".join(words)


def cardinal(n: int) -> str:
    """4 -> "four", -3 -> "minus three", 1200 -> "one thousand two hundred"."""
    if n < 0:
        return f"minus {cardinal(-n)}"
    if n > MAX_CARDINAL:
        return digits(str(n))
    if n < 1000:
        return _below_thousand(n) if n else "zero"
    words = []
    for scale, name in SCALES:
        count, n = divmod(n, scale)
        if count:
            words.append(f"{_below_thousand(count)} {name}")
    if n:
        words.append(_below_thousand(n))
    return " ".join(words)


def ordinal(n: int) -> str:
    """1 -> "first", 22 -> "twenty-second", 100 -> "one hundredth"."""
    words = cardinal(n)
    cut = max(words.rfind(" "), words.rfind("-")) + 1  # the last word changes
    head, last = words[:cut], words[cut:]
    if last in ORDINAL_ENDINGS:
        return head + ORDINAL_ENDINGS[last]
    if last.endswith("y"):
        return head + last[:-1] + "ieth"
    return head + last + "th"


def year(n: int) -> str:
    """A year as it is said: 1984 -> "nineteen eighty-four", 1905 -> "nineteen oh five"."""
    high, low = divmod(n, 100)
    if not 11 <= high <= 19 or low == 0:
        return cardinal(n)
    return f"{_below_hundred(high)} {'oh ' + ONES[low] if low < 10 else _below_hundred(low)}"


def digits(text: str) -> str:
    """Each digit as a word: "007" -> "zero zero seven"."""
    return " ".join(ONES[int(c)] for c in text if c.isdigit())


def decimal(text: str) -> str:
    """A number as written, with an optional sign, thousands commas and decimals:
    "12.5" -> "twelve point five", "-3" -> "minus three", "1,000" -> "one thousand"."""
    sign = "minus " if text.startswith("-") else ""
    whole, _, fraction = text.lstrip("+-").replace(",", "").partition(".")
    if len(whole) > MAX_CARDINAL_DIGITS:  # read digit by digit; never made an int
        words = digits(whole)
    else:
        words = cardinal(int(whole)) if whole else "zero"
    if fraction:
        words += f" point {digits(fraction)}"
    return sign + words
