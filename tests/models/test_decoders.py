"""The ssd decoder's layout rules, on a hand-built output: no SSD-layout model ships in a
registry package this project can reach, so its real-model check waits for one (the yolox
and yolov8 decoders are checked on real models in test_declared_models and test_models)."""

from __future__ import annotations

import numpy as np
import pytest

from oricf.errors import InvalidInput
from oricf.models.decoders import DECODERS


def ssd_output(rows: list[list[float]]) -> np.ndarray:
    return np.array(rows, np.float32).reshape(1, 1, len(rows), 7)


def test_ssd_rows_become_pixel_boxes_until_the_end_marker() -> None:
    decode = DECODERS["ssd"]((400, 200), [], 2)
    output = ssd_output([
        [0, 1, 0.9, 0.1, 0.2, 0.5, 0.6],
        [0, 0, 0.3, 0.0, 0.0, 1.0, 1.0],    # under min_score
        [0, 7, 0.95, 0.0, 0.0, 1.0, 1.0],   # a class id beyond the labels
        [-1, 0, 0.99, 0.0, 0.0, 1.0, 1.0],  # the end of the list: ignored
    ])
    boxes, scores, classes = decode(output, 0.5, None)
    np.testing.assert_allclose(boxes, [[40, 40, 200, 120]], rtol=1e-6)
    assert scores.tolist() == pytest.approx([0.9]) and classes.tolist() == [1]
    _, _, only_zero = decode(output, 0.1, np.array([0]))
    assert only_zero.tolist() == [0]


def test_a_decoder_refuses_an_output_of_another_layout() -> None:
    with pytest.raises(InvalidInput, match=r"ssd decoder: output shape \[1, 100, 85\]"):
        DECODERS["ssd"]((416, 416), [], 80)(np.zeros((1, 100, 85), np.float32), 0.5, None)
    with pytest.raises(InvalidInput, match="yolox decoder: 100 rows"):
        DECODERS["yolox"]((416, 416), [8, 16, 32], 80)(np.zeros((1, 100, 85), np.float32),
                                                       0.5, None)
