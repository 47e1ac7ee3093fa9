"""How an image becomes a model's input tensor, as a declaration says: a detector's
`task.image`, and each of a policy's `task.images`."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from oricf.config import Schema


class ImageInput(Schema):
    """How an image becomes the model's input tensor: (pixel * scale - mean) / std."""

    input: str | None = Field(None, description="the model input it feeds (default: first)")
    size: tuple[int, int] | None = Field(
        None, description="[width, height] of the network input (default: from the model)")
    resize: Literal["letterbox", "stretch"] = Field(
        "letterbox", description="letterbox keeps the aspect ratio and pads")
    align: Literal["top_left", "center"] = Field(
        "top_left", description="letterbox: where the resized image sits")
    pad_value: int = Field(114, ge=0, le=255)
    color: Literal["bgr", "rgb"] = "bgr"
    scale: float = Field(1.0, gt=0, description="e.g. 0.00392156862745098 for 0-1 values")
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    layout: Literal["nchw", "nhwc"] = "nchw"
    datatype: Literal["FP32", "FP16", "UINT8"] = "FP32"

    @model_validator(mode="after")
    def _positive(self) -> ImageInput:
        if self.size is not None and min(self.size) < 1:
            raise ValueError("size: width and height must be >= 1")
        if min(self.std) <= 0:
            raise ValueError("std: every value must be > 0")
        return self
