"""count: {label: person, into: count} counts detections (of one label, or all). The one
place detections are counted."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


class CountStep(Schema):
    label: str | None = Field(None, description="count only this label (default: all)")
    into: str = "count"


class Count(Step[CountStep]):
    reads = frozenset({"detections"})

    def __init__(self, settings: CountStep) -> None:
        super().__init__(settings)
        self.writes = settings.into

    def run(self, record: Record) -> None:
        detections, label = record["detections"], self.settings.label
        record[self.settings.into] = (len(detections) if label is None
                                      else sum(1 for d in detections if d.label == label))


COMPONENT = StepKind("count", CountStep, Count, rank=2)
