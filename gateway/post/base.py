"""What every post step is once built: the record fields it reads, the one it writes (if
any), and the function that runs it on a record."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from oricf.gateway.values import Record

Run = Callable[[Record], None]


@dataclass(frozen=True)
class Step:
    reads: frozenset[str]
    writes: str | None
    run: Run
