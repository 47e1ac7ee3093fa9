"""An image becomes a model input as its declaration says: (pixel * scale - mean) / std per
channel, in the declared colour order, layout and datatype, the image letterboxed into it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from oricf.models.declaration import ImageInput
from oricf.models.image import to_tensor
from tests.support.data import image

SIZE = (416, 416)


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return cv2.imread(str(image("kite.jpg")))


def by_definition(image: np.ndarray, settings: ImageInput) -> np.ndarray:
    """The declared formula spelt out one step at a time, in float64."""
    height, width = image.shape[:2]
    scale = min(SIZE[0] / width, SIZE[1] / height)
    new_w, new_h = int(width * scale), int(height * scale)
    canvas = np.full((SIZE[1], SIZE[0], 3), settings.pad_value, np.uint8)
    canvas[:new_h, :new_w] = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    if settings.color == "rgb":
        canvas = canvas[:, :, ::-1]
    values = canvas.astype(np.float64) * settings.scale
    values = (values - np.array(settings.mean)) / np.array(settings.std)
    if settings.layout == "nchw":
        values = values.transpose(2, 0, 1)
    return values[np.newaxis]


@pytest.mark.parametrize("declared", [
    {},
    {"color": "rgb", "scale": 1 / 255, "mean": [0.485, 0.456, 0.406],
     "std": [0.229, 0.224, 0.225]},
    {"layout": "nhwc", "color": "rgb", "mean": [10, 20, 30], "std": [2, 4, 8]},
    {"datatype": "FP16", "scale": 1 / 255},
])
def test_the_tensor_follows_the_declared_formula(photo: np.ndarray, declared: dict) -> None:
    settings = ImageInput(size=SIZE, **declared)
    tensor, _ = to_tensor(photo, settings, SIZE)
    expected = by_definition(photo, settings)
    assert tensor.shape == expected.shape and tensor.flags.c_contiguous
    assert tensor.dtype == (np.float16 if settings.datatype == "FP16" else np.float32)
    np.testing.assert_allclose(tensor.astype(np.float64), expected, rtol=2e-3, atol=1e-3)
    # The channels really differ on this photo: a swapped or mixed-up plane would show.
    channel_axis = 1 if settings.layout == "nchw" else 3
    means = expected.mean(axis=tuple(a for a in range(4) if a != channel_axis))
    assert np.ptp(means) > 0.01


def test_uint8_inputs_keep_the_bytes_in_the_declared_layout(photo: np.ndarray) -> None:
    planar, _ = to_tensor(photo, ImageInput(size=SIZE, datatype="UINT8"), SIZE)
    packed, _ = to_tensor(photo, ImageInput(size=SIZE, datatype="UINT8", layout="nhwc"), SIZE)
    assert planar.dtype == np.uint8 and planar.shape == (1, 3, *SIZE[::-1])
    np.testing.assert_array_equal(planar[0].transpose(1, 2, 0), packed[0])
