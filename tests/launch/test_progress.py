"""Progress output without a terminal: waiting lines now and then, lasting lines always."""

from __future__ import annotations

import io

from oricf.launch.progress import ProgressLine


def test_plain_output_thins_out_waiting_lines() -> None:
    stream = io.StringIO()
    progress = ProgressLine(stream)
    for second in range(5):
        progress(f"waiting ({second} s)")
    progress("detector SERVING", True)
    assert stream.getvalue().splitlines() == ["waiting (0 s)", "detector SERVING"]


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_terminal_output_rewrites_one_line() -> None:
    stream = Terminal()
    progress = ProgressLine(stream)
    progress("waiting (1 s)")
    progress("waiting (2 s)")
    progress.done("asr SERVING")
    assert stream.getvalue() == ("\r\033[Kwaiting (1 s)\r\033[Kwaiting (2 s)"
                                 "\r\033[Kasr SERVING\n")
