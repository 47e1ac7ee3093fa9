"""The gateway's Infer method against a server nobody here wrote: KServe's ModelServer from
the `kserve` package, serving YOLOX-Nano through a small custom predictor
(tests/interop/kserve_server.py), in a process of its own on loopback."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest

from oricf.bench.common import stop
from oricf.gateway.components import METHODS
from oricf.gateway.endpoints import GrpcTarget, TargetConfig
from oricf.gateway.methods.base import ServingHealth
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.store import ModelStore
from tests.gateway.methods.test_infer import counts, infer_config
from tests.gateway.test_pipeline import FRAMES, run_frames
from tests.support.processes import free_port
from tests.support.services import RunningService

SERVER = Path(__file__).with_name("kserve_server.py")


def wait_ready(address: str, process: subprocess.Popen[str], timeout: float = 60) -> None:
    stub = oip_grpc.GRPCInferenceServiceStub(grpc.insecure_channel(address))
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the KServe server exited: {process.stdout.read()}")  # type: ignore[union-attr]
        try:
            if stub.ServerReady(oip.ServerReadyRequest(), timeout=1).ready:
                return
        except grpc.RpcError:
            pass
        time.sleep(0.2)
    raise TimeoutError(f"KServe at {address} not ready in {timeout} s")


@pytest.fixture(scope="module")
def kserve_address() -> Iterator[str]:
    grpc_port, http_port = free_port(), free_port()
    process = subprocess.Popen(
        [sys.executable, str(SERVER), "--grpc_port", str(grpc_port), "--http_port",
         str(http_port), str(ModelStore().path("yolox-nano"))],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    address = f"127.0.0.1:{grpc_port}"
    try:
        wait_ready(address, process)
        yield address
    finally:
        stop(process)


def test_gateway_counts_people_through_kserve_as_through_oricf(
        kserve_address: str, models: RunningService) -> None:
    at_kserve = {"routes": {"people": {"call": {"model_name": "kserve-yolox"}}}}
    pipeline, through_kserve = run_frames(infer_config(kserve_address, at_kserve), FRAMES)
    _, through_oricf = run_frames(infer_config(models.address), FRAMES)
    assert counts(through_kserve) == counts(through_oricf)
    assert counts(through_kserve)[0] == 4
    assert pipeline.routes["people"].stats.ok == len(FRAMES)


def test_gateway_fails_over_to_kserve_and_probes_it_without_grpc_health(
        kserve_address: str) -> None:
    """KServe does not serve grpc.health.v1: the probe asks ServerReady instead."""
    config = infer_config(f"127.0.0.1:{free_port()}", {
        "endpoints": {"models": {"fallback": kserve_address, "deadline_ms": 5000}},
        "routes": {"people": {"call": {"model_name": "kserve-yolox"}}}})
    pipeline, outputs = run_frames(config, FRAMES[:1])
    assert counts(outputs) == [4]
    endpoint = pipeline.endpoints["models"]
    assert endpoint.failovers == 1
    probe = GrpcTarget(TargetConfig(address=kserve_address), METHODS["Infer"])
    assert probe.serving()
    probe.close()
    with pytest.raises(grpc.RpcError) as error:  # KServe lacks grpc.health.v1
        ServingHealth("inference.GRPCInferenceService")(grpc.insecure_channel(kserve_address), 5)
    assert error.value.code() == grpc.StatusCode.UNIMPLEMENTED
