"""The gateway's people route against NVIDIA Triton Inference Server itself (the server that
nvidia-pytriton bundles, serving YOLOX-Nano: scripts/triton-server.sh), on the frames of the
pedestrian video: the tensor on the wire and in system shared memory, and a camera frame in
with decoded detections back, each counting what the onboard pipeline counts. Marked
`triton` (Triton's environment is installed apart, once): `scripts/test.sh -m triton`."""

from __future__ import annotations

import logging
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import grpc
import numpy as np
import pytest

from oricf.bench.triton import INSTALL, NotInstalled, installed, triton_server
from oricf.config import config_dir, deep_merge
from oricf.gateway.components import METHODS
from oricf.gateway.config import PipelineConfig
from oricf.gateway.endpoints import GrpcTarget, TargetConfig
from oricf.gateway.endpoints.shared_memory import SharedMemoryTransport
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from oricf.models.wire import infer_request
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.gateway.methods.test_infer import counts, infer_config
from tests.gateway.test_pipeline import FRAMES, Outputs, pipeline_config, run_frames
from tests.support.data import video_frames
from tests.support.services import RunningService
from tests.support.waiting import wait_for

pytestmark = pytest.mark.triton

SHM = {"endpoints": {"models": {"image": {"transport": "shm"}}}}
DECODED = {"routes": {"people": {"call": {"model_name": "yolox-nano-decoded",
                                          "decoded": True}}}}


def with_changes(*changes: dict[str, Any]) -> dict[str, Any]:
    merged: dict[str, Any] = {}
    for change in changes:
        merged = deep_merge(merged, change)
    return merged


@pytest.fixture(scope="module")
def triton() -> Iterator[str]:
    try:
        with triton_server() as address:
            yield address
    except NotInstalled as missing:
        pytest.fail(str(missing))


@pytest.fixture(scope="module")
def onboard(detector: RunningService) -> list[int]:
    """The counts of the shipped people route on this host (Detect on ORICF's detector)."""
    _, outputs = run_frames(pipeline_config(detector.address), FRAMES)
    assert counts(outputs)[0] == 4
    return counts(outputs)


def regions(address: str) -> list[str]:
    with grpc.insecure_channel(address) as channel:
        status = oip_grpc.GRPCInferenceServiceStub(channel).SystemSharedMemoryStatus(
            oip.SystemSharedMemoryStatusRequest(), timeout=5)
    return sorted(status.regions)


def unregistered_all(address: str) -> bool:
    """Triton refuses to drop a region that a response it just sent still holds."""
    with grpc.insecure_channel(address) as channel:
        try:
            oip_grpc.GRPCInferenceServiceStub(channel).SystemSharedMemoryUnregister(
                oip.SystemSharedMemoryUnregisterRequest(name=""), timeout=5)
        except grpc.RpcError as error:
            logging.getLogger(__name__).info("unregistering: %s: %s", error.code().name,
                                             error.details())
            return False
    return True


def run_watched(config: PipelineConfig, between: Any = None) -> tuple[Outputs, list[list[str]]]:
    """The frames through a running pipeline, with Triton's shared-memory regions read after
    each (and between(), if given, run after each frame)."""
    outputs = Outputs()
    pipeline = Pipeline(config, outputs)
    address = config.endpoints["models"].address
    seen = []
    pipeline.start()
    try:
        for frame in video_frames(FRAMES):
            loaded = Frame.from_pixels(frame)
            pipeline.submit("people", lambda f=loaded: {"image": f})
            assert pipeline.idle(30)
            seen.append(regions(address))
            if between is not None:
                between(address)
    finally:
        pipeline.stop()
    assert pipeline.routes["people"].stats.ok == len(FRAMES)
    return outputs, seen


@pytest.mark.parametrize("change", [{}, DECODED], ids=["tensor", "decoded"])
def test_people_route_through_triton_counts_as_onboard(
        triton: str, onboard: list[int], change: dict[str, Any]) -> None:
    _, outputs = run_frames(infer_config(triton, change), FRAMES)
    assert counts(outputs) == onboard


@pytest.mark.parametrize("change", [SHM, with_changes(SHM, DECODED)],
                         ids=["tensor", "decoded"])
def test_shared_memory_with_triton_counts_as_onboard(
        triton: str, onboard: list[int], change: dict[str, Any]) -> None:
    outputs, seen = run_watched(infer_config(triton, change))
    assert counts(outputs) == onboard
    # the ring of two regions was registered with Triton and the frames went through it
    assert all(len(names) == 2 and all(n.startswith("oricf-models") for n in names)
               for names in seen), seen
    assert regions(triton) == []  # unregistered when the pipeline stopped


def test_a_triton_that_forgot_the_regions_gets_them_again(
        triton: str, onboard: list[int]) -> None:
    """Triton answers NOT_FOUND for a region it does not know (ORICF's servers
    INVALID_ARGUMENT): the call goes on the wire once and the ring is registered anew."""
    def forget(address: str) -> None:
        wait_for(lambda: unregistered_all(address), 10, "Triton to drop the regions")

    outputs, seen = run_watched(infer_config(triton, SHM), between=forget)
    assert counts(outputs) == onboard
    # each frame after the first found its regions gone: the one after it went on the wire
    # and the next registered a ring again
    assert [len(names) for names in seen] == [2, 0, 2], seen


def test_closing_right_after_a_call_leaves_no_region_registered_with_triton(
        triton: str) -> None:
    """Triton refuses to unregister a region that the response it has just sent still
    holds (INTERNAL, "currently in use"; about one time in six here): the gateway's
    transport asks again until it lets go, so closing right after a call leaves nothing."""
    tensor = np.zeros((1, 3, 416, 416), np.float32)
    target = GrpcTarget(TargetConfig(address=triton), METHODS["Infer"])
    try:
        for _ in range(40):
            shared = SharedMemoryTransport("oricf-closing", "shm")
            shared.call(target, "ModelInfer", 10, [tensor.data.cast("B")],
                        lambda refs: infer_request("yolox-nano", {"images": tensor}, placed=(
                            {"images": refs[0]} if refs else None)),
                        lambda response, region: region)
            shared.close([target])
            assert regions(triton) == []
    finally:
        target.close()


def test_decoded_detections_from_triton_keep_the_routes_min_score(
        triton: str, models: RunningService) -> None:
    """Triton's Python back end does not see the requested output's parameters and decodes
    at its own threshold: the gateway holds the rows to the route's min_score itself."""
    strict = {"routes": {"people": {"call": {"min_score": 0.75}}}}
    _, at_triton = run_frames(infer_config(triton, with_changes(DECODED, strict)), FRAMES)
    _, at_oricf = run_frames(infer_config(models.address, with_changes(strict)), FRAMES)
    _, loose = run_frames(infer_config(triton, DECODED), FRAMES)
    assert counts(at_triton) == counts(at_oricf)
    assert counts(at_triton) != counts(loose)  # the threshold did remove people


def test_a_restricted_shared_memory_protocol_is_refused_once(
        onboard: list[int], caplog: pytest.LogCaptureFixture) -> None:
    """pytriton's default: Triton's shared-memory protocol needs an access token, and says
    UNAVAILABLE without one. That is no server starting up: the gateway says so once and
    sends every frame on the wire, instead of trying to register before each call."""
    try:
        with triton_server("--restrict-shared-memory") as address, \
                caplog.at_level(logging.DEBUG, "oricf.gateway.endpoints.shared_memory"):
            _, outputs = run_frames(infer_config(address, SHM), FRAMES)
    except NotInstalled as missing:
        pytest.fail(str(missing))
    assert counts(outputs) == onboard
    refusals = [r.getMessage() for r in caplog.records if "not possible" in r.getMessage()]
    assert len(refusals) == 1 and "This protocol is restricted" in refusals[0], refusals
    assert not [r for r in caplog.records if "registering with" in r.getMessage()]


def test_a_restricted_shared_memory_protocol_takes_frames_with_its_access_token(
        onboard: list[int], tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """With the access token in the endpoint (`token_header`: the key Triton reads it
    from), the gateway registers its regions with a restricted Triton and every frame goes
    through shared memory."""
    token = tmp_path / "triton-token"
    token.write_text("not-a-real-secret-but-long-enough-0123456789\n")
    keyed = {"endpoints": {"models": {
        "token": {"file": str(token)},
        "token_header": "triton-grpc-protocol-triton-access-token"}}}
    try:
        with triton_server("--restrict-shared-memory", "--access-token-file", str(token)
                           ) as address, \
                caplog.at_level(logging.DEBUG, "oricf.gateway.endpoints.shared_memory"):
            _, outputs = run_frames(infer_config(address, with_changes(SHM, keyed)), FRAMES)
    except NotInstalled as missing:
        pytest.fail(str(missing))
    assert counts(outputs) == onboard
    messages = [r.getMessage() for r in caplog.records]
    assert not [m for m in messages if "not possible" in m], messages
    assert [m for m in messages if "shared-memory regions of" in m and "registered" in m], \
        messages


def test_bench_models_measures_triton_beside_oricfs_server() -> None:
    if not installed():
        pytest.fail(f"Triton is not installed: run {INSTALL}")
    done = subprocess.run([sys.executable, "-m", "oricf", "bench", "models", "--frames", "3",
                           "--triton"], capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    rows = {line.split("  ")[0] for line in done.stdout.splitlines()}
    assert {"ModelInfer raw tensor", "ModelInfer shm", "Triton raw tensor", "Triton shm",
            "Triton uint8, decoded"} <= rows, done.stdout
    assert "beside it, Triton: the tensor on the wire" in done.stdout


def test_bench_models_refuses_triton_for_a_model_it_does_not_serve() -> None:
    done = subprocess.run([sys.executable, "-m", "oricf", "bench", "models", "--triton",
                           "--model", str(config_dir() / "models" / "yolov8-fall.yaml")],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "serves yolox-nano only" in done.stderr, done.stderr
