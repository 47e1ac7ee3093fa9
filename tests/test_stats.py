"""One percentile for the gateway's placement and the benchmarks' tables."""

from __future__ import annotations

from collections import deque

import pytest

from oricf.stats import p90, percentile


def test_the_p90_is_a_value_measured_at_or_above_the_90th_rank() -> None:
    assert p90([5.0, 1.0, 4.0, 2.0, 3.0]) == 5.0  # a window of 5: its slowest call
    assert p90(deque(float(v) for v in range(1, 21))) == 19.0
    assert p90(range(1, 11)) == 10.0
    assert p90([7.5]) == 7.5
    assert percentile([1.0, 2.0, 3.0, 4.0], 50) == 3.0


def test_no_values_is_an_error() -> None:
    with pytest.raises(IndexError):
        p90([])
