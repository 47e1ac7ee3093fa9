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


class LineCrossings(Step[LineStep]):
    def __init__(self, settings: LineStep) -> None:
        super().__init__(settings)
        self.reads, self.writes = frozenset({settings.tracks}), settings.into
        self.line = Line(settings.start, settings.end, settings.label, settings.anchor,
                         settings.window_s)

    def run(self, record: Record) -> None:
        step = self.settings
        record[step.into] = self.line.update(record[step.tracks])[step.measure]


COMPONENT = StepKind("line", LineStep, LineCrossings, rank=9)
