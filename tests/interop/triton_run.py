"""Runs one of the Triton client scripts beside this file against `oricf serve models` in
a real process, on the YOLOX-Nano input of person.jpg."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from oricf.config import REPO_ROOT
from oricf.models.declaration import load_declaration
from oricf.models.heads import declared_head
from oricf.store import ModelStore
from tests.support.data import image
from tests.support.processes import free_port, oricf_process, wait_serving


def run_client(script: str, tmp_path: Path, *args: str,
               outputs: tuple[str, ...] = ("output.npy",)) -> dict[str, Any]:
    """The script's JSON summary, after checking that each output it saved in tmp_path
    (`outputs`) equals onnxruntime's in this process on the same input; the input tensor is
    `input`. The script's arguments: the server's address, input.npy, output.npy, `args`."""
    import onnxruntime as ort

    head = declared_head(load_declaration(REPO_ROOT / "configs/models/yolox-nano.yaml"))
    tensor = head.prepare(cv2.imread(str(image("person.jpg")))).feeds["images"]
    np.save(tmp_path / "input.npy", tensor)
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "models", "--listen", address) as server:
        wait_serving(address, process=server)
        result = subprocess.run(
            [sys.executable, str(Path(__file__).with_name(script)), address,
             str(tmp_path / "input.npy"), str(tmp_path / "output.npy"), *args],
            capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    local = ort.InferenceSession(str(ModelStore().path("yolox-nano"))).run(
        None, {"images": tensor})[0]
    for name in outputs:
        np.testing.assert_allclose(np.load(tmp_path / name), local, rtol=1e-5, atol=1e-5,
                                   err_msg=name)
    summary: dict[str, Any] = json.loads(result.stdout)
    summary["input"] = tensor
    return summary
