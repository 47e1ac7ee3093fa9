"""compose/convert_models.py, the image build's step after `oricf models pull`, run for real
on a model store of its own: the baked policy's weights become its ONNX model from the
verified source (never the copy a seeded store brought), models without `convert:` are left
alone, and the policy service then loads from that store without writing to it, as it must
in the image, where the store is not its user's."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from oricf.config import REPO_ROOT, config_dir
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.store import ModelStore

SCRIPT = REPO_ROOT / "compose" / "convert_models.py"
HOPPER = config_dir() / "models" / "policies" / "hopper.yaml"


def seeded_store(root: Path) -> Path:
    """A store holding the Hopper policy's weights and a stale ONNX file beside them."""
    source = ModelStore().path("pybullet-hopper")
    folder = root / "pybullet-hopper"
    folder.mkdir(parents=True)
    shutil.copy2(source, folder / source.name)
    stale = folder / f"{ModelStore().entry('pybullet-hopper').files[0].sha256}.onnx"
    stale.write_bytes(b"not the converted model")
    return folder


def convert(store: Path, *models: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *models], capture_output=True,
                          text=True, timeout=120, check=False,
                          env={**os.environ, "ORICF_MODEL_DIR": str(store)})


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.iterdir()}


def test_the_build_converts_the_policy_from_its_verified_source(tmp_path: Path) -> None:
    folder = seeded_store(tmp_path)
    result = convert(tmp_path, "yolox-nano", "pybullet-hopper")
    assert result.returncode == 0, result.stderr
    assert "pybullet-hopper: converted to" in result.stderr
    (onnx,) = folder.glob("*.onnx")
    assert onnx.read_bytes() != b"not the converted model"
    assert not (tmp_path / "yolox-nano").exists()   # named, but nothing to convert

    before = snapshot(folder)
    policy = PolicyModel(load_declaration(HOPPER), ModelStore(root=tmp_path))
    policy.load()
    try:
        actions = policy.act(np.zeros(15, np.float32))
    finally:
        policy.close()
    assert actions.shape == (1, 3) and np.all(np.abs(actions) <= 1.0)
    assert snapshot(folder) == before   # loaded as it is: nothing written, nothing made


def test_models_not_named_are_not_converted(tmp_path: Path) -> None:
    folder = seeded_store(tmp_path)
    result = convert(tmp_path, "yolox-nano")
    assert result.returncode == 0, result.stderr
    assert [p.read_bytes() for p in folder.glob("*.onnx")] == [b"not the converted model"]


def test_a_missing_source_fails_the_build_naming_it(tmp_path: Path) -> None:
    result = convert(tmp_path, "pybullet-hopper")
    assert result.returncode == 1
    assert "pybullet-hopper" in result.stderr and "oricf models pull" in result.stderr


def test_no_model_named_is_a_usage_error(tmp_path: Path) -> None:
    result = convert(tmp_path)
    assert result.returncode == 2 and "convert_models.py MODEL" in result.stderr
