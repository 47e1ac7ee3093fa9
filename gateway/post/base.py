"""What every post step is once built (oricf.gateway.components.Step): a class built from its
settings, with the record fields it reads, the one it writes (if any), and its `run`."""

from __future__ import annotations

from oricf.gateway.components import Step, StepKind

__all__ = ["Step", "StepKind"]
