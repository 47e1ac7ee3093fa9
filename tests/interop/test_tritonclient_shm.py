"""Triton's client and its own shared-memory utilities against `oricf serve models` in a
real process: register an input and an output region, infer through them (outputs equal to
onnxruntime in process on the same file), read the status, unregister one and then all."""

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

CLIENT = Path(__file__).with_name("triton_shm_client.py")


def test_tritonclient_shared_memory_infers_like_onnxruntime(tmp_path: Path) -> None:
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
    regions = summary["status"]["regions"]
    assert regions["input_data"]["key"] == "/triton_in"
    assert int(regions["input_data"]["byte_size"]) == tensor.nbytes
    assert int(regions["output_data"]["byte_size"]) == 3549 * 85 * 4
    # the answer names where the output went, as Triton's does
    placed = summary["placed"]
    assert placed["shape"] == ["1", "3549", "85"]
    assert placed["parameters"]["shared_memory_region"]["string_param"] == "output_data"
    assert list(summary["after_one"]["regions"]) == ["output_data"]
    assert summary["after_all"] == {}
    served = np.load(tmp_path / "output.npy")
    local = ort.InferenceSession(str(ModelStore().path("yolox-nano"))).run(
        None, {"images": tensor})[0]
    np.testing.assert_allclose(served, local, rtol=1e-5, atol=1e-5)
    assert not list(Path("/dev/shm").glob("triton_*"))  # tritonclient removed its own
