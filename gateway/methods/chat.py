"""Generate as an OpenAI chat completion: the prompt as the user's message, the context's
facts rendered into a system message by the call's templates (the same stale rules as over
gRPC: left out, or marked), and optionally the newest camera frame as an image part for a
vision-language model."""

from __future__ import annotations

import base64
import logging
from typing import Any

import numpy as np
from pydantic import Field, field_validator

from oricf.config import Schema
from oricf.gateway.products import ProductStore, Reading
from oricf.gateway.values import Frame, template_fields
from oricf.imaging import encode_image

log = logging.getLogger(__name__)

FACT_FIELDS = {"name", "value", "age_s", "stale"}


class ImageContext(Schema):
    """The newest frame of a data product (a camera route's `{product: NAME, from: image}`
    output), attached to the question as a JPEG image part."""

    product: str = Field(description="a data product whose values are camera frames")
    max_side: int = Field(640, ge=32, le=4096, description="scaled down to fit, if larger")
    jpeg_quality: int = Field(80, ge=1, le=100)


class ChatTemplates(Schema):
    """How the context's facts become a system message, for servers that take no typed
    facts (the OpenAI-compatible API). `{facts}` is the facts' lines; each line is `fact`
    filled with name, value, age_s and stale (', stale' when marked, else empty)."""

    system: str = Field("What the robot's sensors say now, each with its age:\n{facts}")
    fact: str = Field("- {name}: {value} ({age_s:.1f} s ago{stale})")

    @field_validator("system")
    @classmethod
    def _system(cls, value: str) -> str:
        unknown = template_fields(value) - {"facts"}
        if unknown:
            raise ValueError(f"only {{facts}} can be filled in, not {sorted(unknown)}")
        return value

    @field_validator("fact")
    @classmethod
    def _fact(cls, value: str) -> str:
        unknown = template_fields(value) - FACT_FIELDS
        if unknown:
            raise ValueError(f"only {sorted(FACT_FIELDS)} can be filled in, not "
                             f"{sorted(unknown)}")
        return value


def fact_line(template: str, reading: Reading) -> str:
    value = "unknown" if reading.value is None else reading.value
    return template.format(name=reading.name, value=value, age_s=reading.age_s,
                           stale=", stale" if reading.stale else "")


def messages(prompt: str, readings: list[Reading], templates: ChatTemplates,
             image: str | None) -> list[dict[str, Any]]:
    """The chat: a system message with the facts (if any), then the question."""
    chat: list[dict[str, Any]] = []
    if readings:
        lines = "\n".join(fact_line(templates.fact, r) for r in readings)
        chat.append({"role": "system", "content": templates.system.format(facts=lines)})
    if image is None:
        chat.append({"role": "user", "content": prompt})
    else:
        chat.append({"role": "user", "content": [
            {"type": "text", "text": prompt},
            {"type": "image_url", "image_url": {"url": image}}]})
    return chat


def image_url(products: ProductStore, image: ImageContext) -> str | None:
    """The product's newest frame as a data: URL, or None if there is none or it is stale
    (an old picture is never passed off as what the camera sees now)."""
    reading = products.read(image.product)
    if reading is None or reading.stale:
        log.debug("no current frame in %s: asking without an image", image.product)
        return None
    if not isinstance(reading.value, Frame):
        log.warning("data product %s holds no image (%s): asking without one",
                    image.product, type(reading.value).__name__)
        return None
    pixels = fit(reading.value.pixels(), image.max_side)
    jpeg = encode_image(pixels, "jpeg", image.jpeg_quality)
    return "data:image/jpeg;base64," + base64.b64encode(jpeg).decode("ascii")


def fit(pixels: np.ndarray, max_side: int) -> np.ndarray:
    import cv2  # here: a pipeline's schema, which names this method, loads no OpenCV

    height, width = pixels.shape[:2]
    scale = max_side / max(height, width)
    if scale >= 1:
        return pixels
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    return cv2.resize(pixels, size, interpolation=cv2.INTER_AREA)
