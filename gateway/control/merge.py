"""How a control loop merges the actions that two or more chunks give for one step: the merge
modes, one entry each in `MERGES` (a name and its settings class, whose fields are its keys in
the pipeline YAML and whose `combine` merges), as LeRobot's `AGGREGATE_FUNCTIONS` has them.

    merge: ensemble                  # a mode by its name, its settings at their defaults
    merge: {mode: weighted, weight: 0.5}

    latest    the newer chunk's action wins (LeRobot's latest_only)
    weighted  old * (1 - weight) + new * weight, chunk by chunk (LeRobot's weighted_average,
              weight 0.7)
    ensemble  every chunk that predicted the step, weighted exp(-k * i) with i = 0 for the
              oldest (ACT's temporal ensembling, k 0.01)

A new mode is a `MergeMode` subclass and its entry here; the control input's settings find it
by name when the pipeline is read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, Field, SerializeAsAny, ValidationError

from oricf.config import Schema


class MergeMode(Schema):
    """A merge mode's settings (its keys beside `mode:`), and how it merges."""

    def combine(self, actions: Sequence[np.ndarray]) -> np.ndarray:
        """The action for a step from those the chunks gave for it, oldest chunk first (two
        or more)."""
        raise NotImplementedError


class Latest(MergeMode):
    def combine(self, actions: Sequence[np.ndarray]) -> np.ndarray:
        return actions[-1]


class Weighted(MergeMode):
    weight: float = Field(0.7, ge=0, le=1, description="the newer chunk's share")

    def combine(self, actions: Sequence[np.ndarray]) -> np.ndarray:
        merged = actions[0]
        for newer in actions[1:]:
            merged = merged * (1 - self.weight) + newer * self.weight
        return merged


class Ensemble(MergeMode):
    k: float = Field(0.01, ge=0, le=100, description="how fast newer chunks' weights fall")

    def combine(self, actions: Sequence[np.ndarray]) -> np.ndarray:
        weights = np.array([math.exp(-self.k * i) for i in range(len(actions))])
        return np.asarray((weights[:, None] * np.stack(actions)).sum(0) / weights.sum())


MERGES: dict[str, type[MergeMode]] = {"latest": Latest, "weighted": Weighted,
                                      "ensemble": Ensemble}


def merge_mode(given: Any) -> MergeMode:
    """The merge mode a YAML value names (`NAME`, or `{mode: NAME, its keys}`), its settings
    checked (ValueError naming the key); a MergeMode as it is."""
    if isinstance(given, MergeMode):
        return given
    settings: dict[str, Any] = {}
    if isinstance(given, Mapping):
        settings = dict(given)
        given = settings.pop("mode", None)
    if not isinstance(given, str) or given not in MERGES:
        raise ValueError(f"a merge mode: {' | '.join(MERGES)}, or {{mode: NAME, its keys}}")
    try:
        return MERGES[given].model_validate(settings)
    except ValidationError as exc:
        error = exc.errors()[0]
        where = ".".join(str(part) for part in error["loc"])
        raise ValueError(f"{given}: {where}: {error['msg']}") from None


# A merge mode as a settings field: its name or its mapping in YAML, found in MERGES when
# the pipeline is read (so a mode added to the table is taken without a schema rebuilt).
Merge = Annotated[SerializeAsAny[MergeMode], BeforeValidator(merge_mode)]
