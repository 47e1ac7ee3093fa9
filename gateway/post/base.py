"""What every post step is once built (oricf.gateway.components.Step): the record fields it
reads, the one it writes (if any), and the function that runs it on a record."""

from __future__ import annotations

from oricf.gateway.components import Run, Step, StepKind

__all__ = ["Run", "Step", "StepKind"]
