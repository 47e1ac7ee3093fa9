"""What every source that is not a ROS topic provides: it runs on a thread of its own, hands
each item to its route as a loader (`submit`), and says when it has ended for good
(`on_end`, e.g. a file that reached its end)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from oricf.gateway.config import InputConfig
from oricf.gateway.route import Loader

Submit = Callable[[Loader], None]
OnEnd = Callable[[str], None]


class Source(Protocol):
    route: str

    def start(self) -> None: ...

    def stop(self, timeout: float = 5.0) -> None: ...


SourceFactory = Callable[[str, InputConfig, Submit, OnEnd], Source]
