"""SIGKILL on either side of a shared-memory route leaves nothing in /dev/shm: the gateway
releases each object's name as soon as the detector holds it open, and the detector, which
creates none, frees a dead gateway's regions when the next client needs their room. A detector
that restarted has forgotten the regions: the gateway sends that call on the wire and
registers a new ring on the next."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import grpc
import pytest

from oricf.config import REPO_ROOT
from oricf.gateway.endpoints import Endpoint, EndpointConfig
from oricf.gateway.methods.detect import METHOD, DetectCall
from oricf.gateway.values import Frame
from oricf.models.shared_memory import OWN_PREFIX, OwnedRegion
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.support.data import video_frames
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import running_service

CHILD = Path(__file__).with_name("shm_gateway_child.py")


def objects(pid: int) -> list[str]:
    return [p.name for p in Path("/dev/shm").glob(f"{OWN_PREFIX}{pid}_*")]


def regions(channel: grpc.Channel) -> list[str]:
    stub = oip_grpc.GRPCInferenceServiceStub(channel)
    return sorted(stub.SystemSharedMemoryStatus(oip.SystemSharedMemoryStatusRequest(),
                                                timeout=10).regions)


def test_a_gateway_killed_mid_stream_leaves_nothing() -> None:
    # Room for the child's ring alone: the next registration needs the dead one's room.
    with running_service("detector", {"shared_memory": {"max_regions": 2}}) as detector:
        child = subprocess.Popen([sys.executable, str(CHILD), detector.address],
                                 stdout=subprocess.PIPE, text=True, cwd=REPO_ROOT,
                                 env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
        try:
            assert child.stdout is not None
            assert child.stdout.readline().strip() == "4"  # vtest.avi frame 0: 4 people
            assert len(regions(detector.channel)) == 2  # the child's ring, in use
            child.send_signal(signal.SIGKILL)
            child.wait(timeout=10)
        finally:
            if child.poll() is None:
                child.kill()
        assert objects(child.pid) == []
        # The next client to register finds the dead one's regions gone (their memory freed).
        owned = OwnedRegion(64)
        try:
            oip_grpc.GRPCInferenceServiceStub(detector.channel).SystemSharedMemoryRegister(
                oip.SystemSharedMemoryRegisterRequest(name="next", key=owned.key,
                                                      byte_size=64), timeout=10)
            assert regions(detector.channel) == ["next"]
        finally:
            owned.close()


def test_a_detector_killed_mid_stream_leaves_nothing() -> None:
    before = sorted(p.name for p in Path("/dev/shm").iterdir()
                    if p.name.startswith((OWN_PREFIX, "triton")))
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "detector", "--listen", address) as server:
        wait_serving(address, process=server)
        endpoint = Endpoint("detector", EndpointConfig(address=address, deadline_ms=30_000,
                                                       image={"transport": "shm"}), METHOD)
        products: Any = None
        invoke = METHOD.open(DetectCall(method="Detect", service="detector"), endpoint,
                             products)
        frame = Frame.from_pixels(video_frames([0])[0])
        try:
            assert len(invoke({"image": frame}).detections) >= 4
            assert objects(os.getpid()) == []  # names released once the server held them
            os.killpg(server.pid, signal.SIGKILL)
            server.wait(timeout=10)
            with pytest.raises(grpc.RpcError) as caught:
                invoke({"image": frame})
            assert caught.value.code() in (grpc.StatusCode.UNAVAILABLE,
                                           grpc.StatusCode.DEADLINE_EXCEEDED)
        finally:
            invoke.close()
            endpoint.close()
    after = sorted(p.name for p in Path("/dev/shm").iterdir()
                   if p.name.startswith((OWN_PREFIX, "triton")))
    assert after == before


def test_a_detector_restarted_gets_the_regions_registered_again(
        caplog: pytest.LogCaptureFixture) -> None:
    address = f"127.0.0.1:{free_port()}"
    frame = Frame.from_pixels(video_frames([0])[0])
    endpoint = Endpoint("detector", EndpointConfig(address=address, deadline_ms=30_000,
                                                   image={"transport": "shm"}), METHOD)
    products: Any = None
    invoke = METHOD.open(DetectCall(method="Detect", service="detector"), endpoint, products)
    try:
        with oricf_process("serve", "detector", "--listen", address) as server:
            wait_serving(address, process=server)
            assert len(invoke({"image": frame}).detections) >= 4
        with oricf_process("serve", "detector", "--listen", address) as server, \
                caplog.at_level(logging.INFO, "oricf.gateway.endpoints.shared_memory"):
            wait_serving(address, process=server)
            # the new process knows no region: this call goes on the wire, the next
            # registers a new ring
            assert len(invoke({"image": frame}).detections) >= 4
            assert "forgot its shared-memory regions" in caplog.text
            assert len(invoke({"image": frame}).detections) >= 4
            assert "regions of 1327104 bytes registered" in caplog.text
            stub = oip_grpc.GRPCInferenceServiceStub(endpoint.primary.channel)
            assert len(stub.SystemSharedMemoryStatus(
                oip.SystemSharedMemoryStatusRequest(), timeout=10).regions) == 2
    finally:
        invoke.close()
        endpoint.close()
