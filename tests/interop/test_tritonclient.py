"""Triton's client, which nobody here wrote, against `oricf serve models` in a real process:
readiness, metadata, and ModelInfer results equal to onnxruntime in process on the same file."""

from __future__ import annotations

from pathlib import Path

from tests.interop.triton_run import run_client


def test_tritonclient_reads_metadata_and_infers_like_onnxruntime(tmp_path: Path) -> None:
    summary = run_client("triton_client.py", tmp_path)
    assert summary["live"] and summary["ready"] and summary["model_ready"]
    assert summary["server"] == "oricf" and summary["id"] == "triton-1"
    # the batch dimension is free (the declaration frees it so the service can batch): -1
    assert summary["inputs"] == [{"name": "images", "datatype": "FP32",
                                  "shape": ["-1", "3", "416", "416"]}]
    assert summary["outputs"][0]["shape"] == ["-1", "3549", "85"]
    assert summary["unknown_model"] == "StatusCode.NOT_FOUND"
    assert summary["unknown_input"] == "StatusCode.INVALID_ARGUMENT"
