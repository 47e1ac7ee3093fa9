"""model.gpu_layers: layers asked for on a GPU run on the CPU where llama.cpp was built
without a GPU back end, and one log line says so; where the model runs is in its info."""

from __future__ import annotations

import logging

import pytest

from oricf.services.llm.domain import GenerationRequest
from oricf.services.llm.service import create_model
from oricf.services.local import service_config
from oricf.store import ModelStore


def test_gpu_layers_without_a_gpu_back_end_run_on_the_cpu(
        caplog: pytest.LogCaptureFixture) -> None:
    config = service_config("llm", {"model": {"gpu_layers": -1}})
    model = create_model(config, ModelStore())
    with caplog.at_level(logging.INFO, logger="oricf.services.llm.model"):
        model.load()
    try:
        warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert warnings == ["model.gpu_layers -1: this llama.cpp was built without a GPU back "
                            "end; the model runs on the CPU (docs/platforms.md: llama.cpp "
                            "with CUDA)"]
        assert any("gemma3-270m loaded on CPU" in r.getMessage() for r in caplog.records)
        info = model.info()
        assert info.providers == ["CPU"] and info.parameters["gpu_layers"] == "-1"
        request = GenerationRequest("How many people do you see?", max_tokens=8)
        text = "".join(chunk.text for chunk in model.generate(request, lambda: None))
        assert text.strip()  # it still answers, on the CPU
    finally:
        model.close()
