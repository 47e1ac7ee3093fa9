"""filter: {labels: [...], min_score} keeps the detections that match both."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


class FilterStep(Schema):
    labels: list[str] = Field(default_factory=list, description="empty: every label")
    min_score: float = Field(0.0, ge=0, le=1)


class Filter(Step[FilterStep]):
    reads = frozenset({"detections"})

    def __init__(self, settings: FilterStep) -> None:
        super().__init__(settings)
        self.labels = set(settings.labels)

    def run(self, record: Record) -> None:
        labels, min_score = self.labels, self.settings.min_score
        record["detections"] = [d for d in record["detections"]
                                if (not labels or d.label in labels) and d.score >= min_score]


COMPONENT = StepKind("filter", FilterStep, Filter, rank=1)
