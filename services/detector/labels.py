"""Label mapping and label filters for the detector."""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence

import numpy as np

from oricf.errors import ConfigError, InvalidInput
from oricf.imaging import Box, Detection
from oricf.models.heads import Detections


class LabelSpace:
    """The detector's output labels: model labels renamed by a label map.

    Several model labels may map to one output label (car, truck -> vehicle); a filter on
    that label then keeps all of them.
    """

    def __init__(self, model_labels: Sequence[str], label_map: Mapping[str, str],
                 default_labels: Sequence[str]) -> None:
        unknown = sorted(set(label_map) - set(model_labels))
        if unknown:
            raise ConfigError(f"detection.label_map: the model has no label(s) "
                              f"{', '.join(unknown)}")
        self.names = [label_map.get(label, label) for label in model_labels]
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

    def resolve(self, requested: Sequence[str]) -> tuple[list[str], np.ndarray | None]:
        """The labels a request keeps and their class ids (None: every class)."""
        labels = list(dict.fromkeys(requested)) or self.default_labels
        unknown = [label for label in labels if label not in self._ids]
        if unknown:
            hints = {u: difflib.get_close_matches(u, self._ids, n=1) for u in unknown}
            described = ", ".join(
                f"'{u}'" + (f" (did you mean '{h[0]}'?)" if h else "") for u, h in hints.items())
            raise InvalidInput(f"unknown label {described}; the detector knows "
                               f"{len(self._ids)} labels (see GetModelInfo)")
        if not labels:
            return [], None
        ids = sorted(i for label in labels for i in self._ids[label])
        return labels, np.array(ids, dtype=np.int64)

    def detections(self, raw: Detections) -> list[Detection]:
        return [
            Detection(self.names[int(c)], int(c), float(s), Box(*map(float, b)))
            for b, s, c in zip(raw.boxes, raw.scores, raw.class_ids, strict=True)
        ]
