"""`infer` over MCP on a model declared in YAML, served by `oricf serve models` (the real
PP-OCR text-direction classifier): an image the agent passes goes through the declaration's
pre- and post-processing, tensors go to the model as they are; bad tensors are MCP errors."""

from __future__ import annotations

import base64
from pathlib import Path

import anyio
import cv2
import numpy as np
import yaml

from oricf.config import config_dir
from tests.gateway.agents.scene import one_frame_video
from tests.gateway.agents.session import stdio_session, text_of
from tests.support.data import text_crops
from tests.support.services import RunningService

MODEL = config_dir() / "models" / "text-direction.yaml"


def upright_tensor(crop: np.ndarray) -> list[float]:
    """The classifier's input as its declaration makes it: 192x48, BGR, -1 to 1, NCHW."""
    pixels = cv2.resize(crop, (192, 48)).astype(np.float32)
    return ((pixels / 255 - 0.5) / 0.5).transpose(2, 0, 1).reshape(-1).tolist()


def test_infer_on_images_and_tensors(tmp_path: Path, models: RunningService) -> None:
    crop = text_crops()[0]
    config = tmp_path / "text.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"models": {"address": models.address, "deadline_ms": 10000}},
        "routes": {"upright": {
            "input": {"url": str(one_frame_video(tmp_path)), "fps": 1, "loop": True},
            "call": {"service": "models", "method": "Infer", "model": str(MODEL)},
            "outputs": [{"product": "text_direction", "from": "label"}]}}}))

    async def scenario() -> None:
        async with stdio_session("--config", str(config)) as session:
            for image, label in [(crop, "0"), (cv2.rotate(crop, cv2.ROTATE_180), "180")]:
                jpeg = base64.b64encode(cv2.imencode(".png", image)[1].tobytes()).decode()
                result = await session.call_tool("infer", {"route": "upright",
                                                           "image": jpeg})
                assert result.structured_content is not None, text_of(result)
                assert result.structured_content["label"] == label

            tensors = {"x": {"datatype": "FP32", "shape": [1, 3, 48, 192],
                             "data": upright_tensor(crop)}}
            raw = await session.call_tool("infer", {"route": "upright",
                                                    "tensors": tensors})
            assert raw.structured_content is not None, text_of(raw)
            (output,) = raw.structured_content["outputs"].values()
            assert output["shape"] == [1, 2] and output["data"][0] > output["data"][1]

            for bad in [{"x": {"datatype": "FP32", "shape": [1, 3], "data": [1.0]}},
                        {"x": {"datatype": "FP99", "shape": [1], "data": [1.0]}},
                        {"x": {"datatype": "FP32", "shape": [10**7], "data": []}},
                        {"x": {"datatype": "FP32", "shape": [1, 3, 48, 192],
                               "data": ["a"] * 27648}},
                        {"nothing": {"datatype": "FP32", "shape": [1], "data": [0]}}]:
                refused = await session.call_tool("infer", {"route": "upright",
                                                            "tensors": bad})
                assert refused.is_error, bad
            both = await session.call_tool("infer", {"route": "upright"})
            assert both.is_error and "image or tensors" in text_of(both)
            assert not (await session.call_tool("status", {})).is_error

    anyio.run(scenario)
