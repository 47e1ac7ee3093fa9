"""The image input of a declared image model, as a client may send it instead of the
network's own tensor, pre-processed here as the declaration says:

    an encoded image   BYTES [1] (or [1, 1]) holding one JPEG or PNG
    raw pixels         UINT8 [H, W, C] (HWC, C 3 or 1), with the input parameter
                       `encoding`: rgb8 (the default for 3 channels), bgr8 or mono8

Either way the server knows the image's size, so it can also return decoded detections
(services/models/decoded.py) with boxes in the image's own pixels.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

import numpy as np

from oricf.errors import InvalidInput
from oricf.imaging import RAW_CHANNELS, decode_image, decoded_bytes, encoded_size, image_size
from oricf.models.declared import DeclaredModel
from oricf.models.heads import Prepared

Feeds = dict[str, np.ndarray]
# (bytes, what) -> a context holding that much of the server's memory budget
Hold = Callable[[int, str], AbstractContextManager[None]]


def image_feeds(model: DeclaredModel, feeds: Feeds, encoding: str, max_pixels: int,
                hold: Hold) -> tuple[Feeds, Prepared | None]:
    """feeds with an image under the image input's name pre-processed into the network's
    tensor, and the prepared image (None when the client sent the network's tensor)."""
    head = model.head
    if head is None or head.input_name not in feeds:
        return feeds, None
    value = feeds[head.input_name]
    spec = model.input(head.input_name)
    if value.dtype == object and spec.datatype != "BYTES":
        pixels = _encoded(head.input_name, value, max_pixels, hold)
    elif value.dtype == np.uint8 and value.ndim == 3 and not spec.accepts_shape(value.shape):
        pixels = _raw(head.input_name, value, encoding, max_pixels)
    else:
        return feeds, None
    prepared = head.prepare(pixels)
    return {**feeds, **prepared.feeds}, prepared


def _encoded(name: str, value: np.ndarray, max_pixels: int, hold: Hold) -> np.ndarray:
    if value.size != 1:
        raise InvalidInput(f"input '{name}': one encoded image per request, got {value.size}")
    data = bytes(value.reshape(-1)[0])
    kind, _, _ = encoded_size(data)  # whichever of the two it is
    width, height = image_size(data, kind, max_pixels=max_pixels)
    with hold(decoded_bytes(width, height), f"a {width}x{height} image"):
        return decode_image(data, kind, max_pixels=max_pixels)


def _raw(name: str, value: np.ndarray, encoding: str, max_pixels: int) -> np.ndarray:
    height, width, channels = value.shape
    encoding = encoding or ("mono8" if channels == 1 else "rgb8")
    if RAW_CHANNELS.get(encoding) != channels:
        raise InvalidInput(f"input '{name}': UINT8 [{height}, {width}, {channels}] with "
                           f"encoding '{encoding[:16]}'; use rgb8 or bgr8 for 3 channels, "
                           f"mono8 for 1")
    # The tensor's bytes were counted in the budget when the request came in.
    return decode_image(value.tobytes(), encoding, width, height, max_pixels)
