"""Triton's client, which nobody here wrote, against `oricf serve models` in a real process:
readiness, metadata, and ModelInfer results equal to onnxruntime in process on the same file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from oricf.config import REPO_ROOT
from oricf.models.declaration import load_declaration
from oricf.models.heads import declared_head
from oricf.store import ModelStore
from tests.support.data import image
from tests.support.processes import free_port, oricf_process, wait_serving

CLIENT = Path(__file__).with_name("triton_client.py")


def test_tritonclient_reads_metadata_and_infers_like_onnxruntime(tmp_path: Path) -> None:
    import onnxruntime as ort

    head = declared_head(load_declaration(REPO_ROOT / "configs/models/yolox-nano.yaml"))
    tensor = head.prepare(cv2.imread(str(image("person.jpg")))).feeds["images"]
    np.save(tmp_path / "input.npy", tensor)
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "models", "--listen", address) as server:
        wait_serving(address, process=server)
        result = subprocess.run(
            [sys.executable, str(CLIENT), address, str(tmp_path / "input.npy"),
             str(tmp_path / "output.npy")], capture_output=True, text=True, timeout=120,
            check=False)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["live"] and summary["ready"] and summary["model_ready"]
    assert summary["server"] == "oricf" and summary["id"] == "triton-1"
    # the batch dimension is free (the declaration frees it so the service can batch): -1
    assert summary["inputs"] == [{"name": "images", "datatype": "FP32",
                                  "shape": ["-1", "3", "416", "416"]}]
    assert summary["outputs"][0]["shape"] == ["-1", "3549", "85"]
    assert summary["unknown_model"] == "StatusCode.NOT_FOUND"
    assert summary["unknown_input"] == "StatusCode.INVALID_ARGUMENT"
    served = np.load(tmp_path / "output.npy")
    local = ort.InferenceSession(str(ModelStore().path("yolox-nano"))).run(
        None, {"images": tensor})[0]
    np.testing.assert_allclose(served, local, rtol=1e-5, atol=1e-5)
