"""The detector's label filter: which of the model's classes a request keeps."""

from __future__ import annotations

import difflib
from collections.abc import Sequence

import numpy as np

from oricf.errors import ConfigError, InvalidInput
from oricf.imaging import Box, Detection
from oricf.models.heads import Detections


class LabelSpace:
    """The detector's labels: the model's own, as its declaration lists them (renaming
    them is the gateway's `map_labels` step). A label listed twice keeps both classes."""

    def __init__(self, model_labels: Sequence[str], default_labels: Sequence[str]) -> None:
        self.names = list(model_labels)
        self._ids: dict[str, list[int]] = {}
        for class_id, name in enumerate(self.names):
            self._ids.setdefault(name, []).append(class_id)
        unknown = sorted(set(default_labels) - set(self._ids))
        if unknown:
            raise ConfigError(f"detection.labels: unknown label(s) {', '.join(unknown)}")
        self.default_labels = list(default_labels)

    @property
    def labels(self) -> list[str]:
        return list(self._ids)

    def resolve(self, requested: Sequence[str]) -> np.ndarray | None:
        """The class ids a request keeps (None: every class)."""
        labels = list(dict.fromkeys(requested)) or self.default_labels
        unknown = [label for label in labels if label not in self._ids]
        if unknown:
            hints = {u: difflib.get_close_matches(u, self._ids, n=1) for u in unknown}
            described = ", ".join(
                f"'{u}'" + (f" (did you mean '{h[0]}'?)" if h else "") for u, h in hints.items())
            raise InvalidInput(f"unknown label {described}; the detector knows "
                               f"{len(self._ids)} labels (see GetModelInfo)")
        if not labels:
            return None
        ids = sorted(i for label in labels for i in self._ids[label])
        return np.array(ids, dtype=np.int64)

    def detections(self, raw: Detections) -> list[Detection]:
        return [
            Detection(self.names[int(c)], int(c), float(s), Box(*map(float, b)))
            for b, s, c in zip(raw.boxes, raw.scores, raw.class_ids, strict=True)
        ]
