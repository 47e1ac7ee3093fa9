"""filter: {labels: [...], min_score} keeps the detections that match both."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


class FilterStep(Schema):
    labels: list[str] = Field(default_factory=list, description="empty: every label")
    min_score: float = Field(0.0, ge=0, le=1)


def build(step: FilterStep) -> Step:
    labels = set(step.labels)

    def run(record: Record) -> None:
        record["detections"] = [d for d in record["detections"]
                                if (not labels or d.label in labels) and d.score >= step.min_score]

    return Step(frozenset({"detections"}), None, run)


COMPONENT = StepKind("filter", FilterStep, build, rank=1)
