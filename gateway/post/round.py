"""round: {field: speed, digits: 1, into: speed_rounded} rounds a number in the record (to
`digits` decimals; 0 gives an int), e.g. a measure before it goes into a template or a
topic. `into` defaults to the field itself."""

from __future__ import annotations

from numbers import Real

from pydantic import Field

from oricf.config import Schema
from oricf.errors import InvalidInput
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


class RoundStep(Schema):
    field: str = Field(description="the record field to round")
    digits: int = Field(0, ge=0, le=12, description="decimals to keep (0: a whole number)")
    into: str | None = Field(None, description="the field to write (default: `field`)")


class Round(Step[RoundStep]):
    def __init__(self, settings: RoundStep) -> None:
        super().__init__(settings)
        self.reads = frozenset({settings.field})
        self.into = settings.into or settings.field
        self.writes = self.into

    def run(self, record: Record) -> None:
        step = self.settings
        value = record[step.field]
        if isinstance(value, bool) or not isinstance(value, Real):
            raise InvalidInput(f"round: {step.field} is not a number")
        record[self.into] = round(value) if step.digits == 0 else round(float(value),
                                                                         step.digits)


COMPONENT = StepKind("round", RoundStep, Round)
