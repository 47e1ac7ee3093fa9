"""oricf.logs.quoted: strings from outside reach a log line escaped and clipped."""

from __future__ import annotations

import pytest

from oricf.errors import InvalidInput
from oricf.gateway.values import compressed_frame, raw_frame
from oricf.imaging import decode_image
from oricf.logs import quoted

HOSTILE = "\x1b[31m\nFAKE LOG LINE" + "x" * 5000


def test_control_characters_are_escaped_and_long_values_clipped() -> None:
    assert quoted("bgr8") == "'bgr8'"
    assert quoted("a\nb\rc\x1b[0m\u2028") == r"'a\nb\rc\x1b[0m\u2028'"
    text = quoted(HOSTILE)
    assert text.startswith(r"'\x1b[31m\nFAKE LOG LINE") and text.endswith("(5,019 characters)")
    assert len(text) < 260 and text.isprintable()
    assert quoted(ValueError("bad\nline"), limit=5) == "'bad\\nl'... (8 characters)"


@pytest.mark.parametrize("refuse", [
    lambda: raw_frame(b"", HOSTILE, 2, 2, 6),
    lambda: compressed_frame(b"x", HOSTILE),
    lambda: decode_image(b"x", HOSTILE),
])
def test_an_encoding_from_outside_is_quoted_in_the_error(refuse: object) -> None:
    with pytest.raises(InvalidInput) as err:
        refuse()  # type: ignore[operator]
    message = str(err.value)
    assert message.isprintable() and len(message) < 400
    assert r"'\x1b[31m\nfake log line" in message.lower()


def test_log_lines_go_to_the_stderr_of_the_moment(monkeypatch: pytest.MonkeyPatch) -> None:
    """A thread that logs after its caller replaced sys.stderr (and closed the old one, as a
    test harness does) writes to the new one, never to the closed one."""
    import io
    import logging
    import sys

    from oricf.logs import setup_logging

    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    first = io.StringIO()
    monkeypatch.setattr(sys, "stderr", first)
    setup_logging("INFO")
    try:
        logging.getLogger("oricf.test").info("one")
        second = io.StringIO()
        monkeypatch.setattr(sys, "stderr", second)
        first.close()
        logging.getLogger("oricf.test").info("two")
        assert "oricf.test: two" in second.getvalue()
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)
