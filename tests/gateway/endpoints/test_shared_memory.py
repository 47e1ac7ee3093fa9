"""Frames through system shared memory (`image.transport: shm` / `auto`) to the real detector
and `oricf serve models` on this host: the counts equal the wire's, the regions are
registered and then unregistered when the pipeline stops, nothing is left in /dev/shm, and
a service that does not offer shared memory gets the wire, with the reason logged once."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from oricf.models.shared_memory import OWN_PREFIX
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.gateway.methods.test_infer import counts, infer_config
from tests.gateway.test_pipeline import FRAMES, pipeline_config, run_frames
from tests.support.services import RunningService, running_service

SHM = {"image": {"transport": "shm"}}


def own_objects() -> list[str]:
    return [p.name for p in Path("/dev/shm").glob(f"{OWN_PREFIX}*")]


def registered(service: RunningService) -> dict[str, object]:
    stub = oip_grpc.GRPCInferenceServiceStub(service.channel)
    return dict(stub.SystemSharedMemoryStatus(oip.SystemSharedMemoryStatusRequest()).regions)


def test_detect_through_shared_memory_counts_as_the_wire(
        caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    before = own_objects()
    _, wire = run_frames(pipeline_config(detector.address), FRAMES)
    with caplog.at_level(logging.INFO, "oricf.gateway.endpoints.shared_memory"):
        _, shared = run_frames(pipeline_config(detector.address,
                                               {"endpoints": {"detector": SHM}}), FRAMES)
    assert registered(detector) == {}  # unregistered when the pipeline stopped
    assert counts(shared) == counts(wire) and counts(shared)[0] == 4
    assert "shared-memory regions of 1327104 bytes registered" in caplog.text  # 768x576x3
    assert "not possible" not in caplog.text
    assert own_objects() == before  # every name released as soon as the server held it


def test_infer_through_shared_memory_with_decoded_detections(
        caplog: pytest.LogCaptureFixture, models: RunningService) -> None:
    decoded = {"routes": {"people": {"call": {"decoded": True}}}}
    _, wire = run_frames(infer_config(models.address), FRAMES)
    with caplog.at_level(logging.INFO, "oricf.gateway.endpoints.shared_memory"):
        _, tensor = run_frames(infer_config(models.address,
                                             {"endpoints": {"models": SHM}}), FRAMES)
    # a slot holds the FP32 input (2,076,672 bytes) and the output (1,206,660)
    assert "regions of 3283332 bytes registered" in caplog.text
    _, small = run_frames(infer_config(models.address, {
        "endpoints": {"models": SHM}, **decoded}), FRAMES)
    _, edge = run_frames(infer_config(models.address, {
        "endpoints": {"models": {"image": {"transport": "jpeg"}}}, **decoded}), FRAMES)
    assert registered(models) == {}
    assert counts(tensor) == counts(wire) == counts(small) and counts(wire)[0] == 4
    assert all(abs(a - b) <= 1 for a, b in zip(counts(edge), counts(wire), strict=True))


def test_a_service_without_shared_memory_gets_the_wire_and_one_log_line(
        caplog: pytest.LogCaptureFixture) -> None:
    off = {"shared_memory": {"enabled": False}}
    with running_service("detector", off) as detector:
        _, wire = run_frames(pipeline_config(detector.address), FRAMES)
        with caplog.at_level(logging.INFO, "oricf.gateway.endpoints.shared_memory"):
            _, auto = run_frames(pipeline_config(detector.address, {"endpoints": {
                "detector": {"image": {"transport": "auto"}}}}), FRAMES)
    assert counts(auto) == counts(wire)
    assert caplog.text.count("not possible (UNIMPLEMENTED") == 1
