"""map_labels: {person: human} renames detection labels (several may become one)."""

from __future__ import annotations

from dataclasses import replace

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record


class MapLabels(Step[dict[str, str]]):
    reads = frozenset({"detections"})

    def run(self, record: Record) -> None:
        mapping = self.settings
        record["detections"] = [replace(d, label=mapping.get(d.label, d.label))
                                for d in record["detections"]]


COMPONENT = StepKind("map_labels", dict[str, str], MapLabels, rank=0)
