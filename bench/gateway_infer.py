"""`oricf bench gateway`'s new edge path: the people route calling Infer on `oricf serve
models` with the frame as JPEG and decoded detections back (a few hundred bytes), instead of
Detect on the edge detector."""

from __future__ import annotations

from typing import Any

from oricf.bench.common import JPEG_QUALITY
from oricf.config import config_dir, deep_merge


def infer_overlay(counting: dict[str, Any], models: str) -> dict[str, Any]:
    """counting, with the people route's call made Infer with decoded detections on the
    models server at `models`."""
    return deep_merge(counting, {
        "endpoints": {"models": {"address": models, "deadline_ms": 800,
                                 "image": {"transport": "jpeg",
                                           "jpeg_quality": JPEG_QUALITY}}},
        "routes": {"people": {"call": {
            "service": "models", "method": "Infer", "labels": ["person"], "decoded": True,
            "model": str(config_dir() / "models" / "yolox-nano.yaml")}}}})
