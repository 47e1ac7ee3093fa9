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


def build(step: CountStep) -> Step:
    label = step.label

    def run(record: Record) -> None:
        detections = record["detections"]
        record[step.into] = (len(detections) if label is None
                             else sum(1 for d in detections if d.label == label))

    return Step(frozenset({"detections"}), step.into, run)


COMPONENT = StepKind("count", CountStep, build, rank=2)
