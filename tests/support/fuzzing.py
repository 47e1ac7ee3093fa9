"""How many examples the slowest fuzz tests draw. The counts written in the tests are the
full ones; the default run draws half of each, from the same strategies, derandomized
(`ORICF_FUZZ_SCALE=1 scripts/test.sh tests/security` draws them all; docs/testing.md)."""

from __future__ import annotations

import os

SCALE = float(os.environ.get("ORICF_FUZZ_SCALE", "0.5"))


def examples(full: int) -> int:
    """The examples to draw of a test whose full count is `full`."""
    return max(10, round(full * SCALE))
