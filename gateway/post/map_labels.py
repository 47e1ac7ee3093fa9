"""map_labels: {person: human} renames detection labels (several may become one)."""

from __future__ import annotations

from dataclasses import replace

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


def build(mapping: dict[str, str]) -> Step:
    def run(record: Record) -> None:
        record["detections"] = [replace(d, label=mapping.get(d.label, d.label))
                                for d in record["detections"]]

    return Step(frozenset({"detections"}), None, run)


COMPONENT = StepKind("map_labels", dict[str, str], build, rank=0)
