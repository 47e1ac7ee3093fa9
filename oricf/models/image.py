"""An image (BGR uint8) -> a model's input tensor, as a declaration's `image:` says, and the
geometry that maps network pixels back to the image."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oricf.models.image_input import ImageInput
from oricf.models.tensors import DATATYPES


@dataclass(frozen=True)
class Geometry:
    """Where the image sits in the network input: network = image * scale + pad."""

    scale_x: float
    scale_y: float
    pad_x: float
    pad_y: float
    width: int    # of the image
    height: int

    def to_image(self, boxes: np.ndarray) -> np.ndarray:
        """(n, 4) x_min, y_min, x_max, y_max in network pixels -> image pixels, clipped."""
        out = np.empty_like(boxes, dtype=np.float32)
        out[:, 0::2] = (boxes[:, 0::2] - self.pad_x) / self.scale_x
        out[:, 1::2] = (boxes[:, 1::2] - self.pad_y) / self.scale_y
        np.clip(out, 0, [self.width, self.height, self.width, self.height], out=out)
        return out


def geometry(width: int, height: int, settings: ImageInput, size: tuple[int, int]
             ) -> Geometry:
    """Where an image of width x height lands in a network input of size (w, h)."""
    net_w, net_h = size
    if settings.resize == "stretch":
        return Geometry(net_w / width, net_h / height, 0.0, 0.0, width, height)
    scale = min(net_w / width, net_h / height)
    new_w, new_h = max(1, int(width * scale)), max(1, int(height * scale))
    pad_x, pad_y = ((net_w - new_w) // 2, (net_h - new_h) // 2) \
        if settings.align == "center" else (0, 0)
    return Geometry(scale, scale, float(pad_x), float(pad_y), width, height)


def to_tensor(image: np.ndarray, settings: ImageInput, size: tuple[int, int]
              ) -> tuple[np.ndarray, Geometry]:
    """A BGR uint8 image -> a batch of one in the declared layout, datatype and range."""
    import cv2  # here: what only declares a model (a pipeline's schema) loads no OpenCV

    height, width = image.shape[:2]
    geo = geometry(width, height, settings, size)
    net_w, net_h = size
    if settings.resize == "stretch":
        canvas = cv2.resize(image, (net_w, net_h), interpolation=cv2.INTER_LINEAR)
    else:
        new_w, new_h = max(1, int(width * geo.scale_x)), max(1, int(height * geo.scale_y))
        canvas = np.full((net_h, net_w, 3), settings.pad_value, dtype=np.uint8)
        x, y = int(geo.pad_x), int(geo.pad_y)
        canvas[y:y + new_h, x:x + new_w] = cv2.resize(image, (new_w, new_h),
                                                      interpolation=cv2.INTER_LINEAR)
    if settings.color == "rgb":
        canvas = cv2.cvtColor(canvas, cv2.COLOR_BGR2RGB)
    dtype = np.dtype(DATATYPES[settings.datatype].numpy)
    planar = settings.layout == "nchw"
    # Planes are split from the bytes, before any float exists: transposing a float image
    # costs many times more, and at some sizes (416 wide) far more, than splitting bytes.
    pixels = np.stack(cv2.split(canvas)) if planar else canvas
    if settings.datatype == "UINT8":
        tensor: np.ndarray = pixels
    else:
        tensor = pixels.astype(np.float32)
        if settings.scale != 1.0:
            tensor *= settings.scale
        if any(settings.mean) or any(s != 1.0 for s in settings.std):
            per_channel = (3, 1, 1) if planar else (1, 1, 3)
            mean = np.array(settings.mean, np.float32).reshape(per_channel)
            std = np.array(settings.std, np.float32).reshape(per_channel)
            tensor = (tensor - mean) / std
    return np.ascontiguousarray(tensor[np.newaxis], dtype=dtype), geo


def network_size(settings: ImageInput, shape: tuple[int, ...]) -> tuple[int, int]:
    """(width, height) of the network input: declared, else from the input's shape."""
    if settings.size is not None:
        return settings.size
    if len(shape) == 4:
        height, width = (shape[2], shape[3]) if settings.layout == "nchw" else shape[1:3]
        if height > 0 and width > 0:
            return int(width), int(height)
    raise ValueError(f"cannot tell the image size from input shape {list(shape)}: "
                     f"give task.image.size")
