"""Summary statistics shared by the gateway and the benchmarks, so that a figure named the
same is computed the same way everywhere."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def percentile(values: Iterable[float], q: float) -> float:
    """The q-th percentile (0-100) of a non-empty collection: the smallest value at or
    above the rank numpy interpolates (its method "higher"), so the figure is always one of
    the values measured, never one between two. Over a window of 5, the 90th is the largest."""
    return float(np.percentile(np.fromiter(values, float), q, method="higher"))


def p90(values: Iterable[float]) -> float:
    """The 90th percentile (see percentile)."""
    return percentile(values, 90)
