"""Triton's client and its own shared-memory utilities against `oricf serve models` in a
real process: register an input and an output region, infer through them (outputs equal to
onnxruntime in process on the same file), read the status, unregister one and then all; the
same with the image instead of the tensor, as UINT8 pixels and as one JPEG (BYTES in Triton's
layout), which the server pre-processes into the same tensor."""

from __future__ import annotations

from pathlib import Path

from tests.interop.triton_run import run_client
from tests.support.data import image


def test_tritonclient_shared_memory_infers_like_onnxruntime(tmp_path: Path) -> None:
    summary = run_client("triton_shm_client.py", tmp_path)
    regions = summary["status"]["regions"]
    assert regions["input_data"]["key"] == "/triton_in"
    assert int(regions["input_data"]["byte_size"]) == summary["input"].nbytes
    assert int(regions["output_data"]["byte_size"]) == 3549 * 85 * 4
    # the answer names where the output went, as Triton's does
    placed = summary["placed"]
    assert placed["shape"] == ["1", "3549", "85"]
    assert placed["parameters"]["shared_memory_region"]["string_param"] == "output_data"
    assert list(summary["after_one"]["regions"]) == ["output_data"]
    assert summary["after_all"] == {}
    assert not list(Path("/dev/shm").glob("triton_*"))  # tritonclient removed its own


def test_tritonclient_shared_memory_takes_uint8_pixels_and_a_jpeg(tmp_path: Path) -> None:
    photo = image("person.jpg")
    summary = run_client("triton_shm_image_client.py", tmp_path, str(photo),
                         str(tmp_path / "jpeg_output.npy"),
                         outputs=("output.npy", "jpeg_output.npy"))
    regions = summary["status"]["regions"]
    assert {name: int(regions[name]["byte_size"]) for name in regions} == summary["sizes"]
    height, width = summary["input_shape"]
    assert summary["sizes"]["pixels"] == height * width * 3
    assert summary["sizes"]["jpeg"] == 4 + photo.stat().st_size  # Triton's length prefix
    status, message = summary["cut"]  # a BYTES element cut short by the declared size
    assert status == "StatusCode.INVALID_ARGUMENT"
    assert "BYTES element 0 claims" in message, message
    assert summary["after"] == {}
    assert not list(Path("/dev/shm").glob("triton_*"))
