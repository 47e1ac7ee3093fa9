"""line: {start: [x, y], end: [x, y], measure: in, into: came_in} counts crossings of a
segment in image pixels by tracks: `in` from the left of start->end to its right as seen
in the image (walking from start to end, the right hand side), `out` the other way; since
the route started, or in the last window_s."""

from __future__ import annotations

from pydantic import field_validator, model_validator

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.post.over_tracks import Placed
from oricf.gateway.post.zone import finite_point
from oricf.gateway.tracking.measures import Line, LineMeasure
from oricf.gateway.values import Record


class LineStep(Placed):
    start: tuple[float, float]
    end: tuple[float, float]
    measure: LineMeasure

    @field_validator("start", "end")
    @classmethod
    def _finite(cls, value: tuple[float, float]) -> tuple[float, float]:
        return finite_point(value)

    @model_validator(mode="after")
    def _a_segment(self) -> LineStep:
        if self.start == self.end:
            raise ValueError("start and end are the same point")
        return self


def build(step: LineStep) -> Step:
    line = Line(step.start, step.end, step.label, step.anchor, step.window_s)

    def run(record: Record) -> None:
        record[step.into] = line.update(record[step.tracks])[step.measure]

    return Step(frozenset({step.tracks}), step.into, run)


COMPONENT = StepKind("line", LineStep, build, rank=9)
