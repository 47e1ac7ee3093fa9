"""The memory budget (server.max_inflight_mb): many concurrent calls with images of tens of
megapixels, or large tensors, are refused beyond the budget with RESOURCE_EXHAUSTED
and pushback, the service goes on serving, and the real service process's peak memory stays
bounded. The models service runs as its own process (`oricf serve models`), so its peak
resident memory is its own."""

from __future__ import annotations

import subprocess
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import grpc
import numpy as np
import pytest

from oricf.models.wire import infer_request
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.services.runtime.limits import PUSHBACK_KEY
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image
from tests.support.detections import count
from tests.support.jpegs import blank
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import CHANNEL_OPTIONS, running_service

BUDGET_MB = 220  # one call of either kind below at a time
CALLS = 16  # at once: twice max_concurrent_rpcs
# Without a budget the 8 admitted calls would hold 8 decoded images (or 8 networks' worth
# of intermediate tensors), well over this; with it, one: the margin is for the allocator
# and for the messages received meanwhile.
MAX_GROWTH_MB = 500
BIG = (6000, 6000)  # a black JPEG of a few hundred kilobytes; 108 MB once decoded


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmHWM for process {pid}")


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], grpc.Channel]]:
    """A models service of its own per test: the peak it reaches is one process-wide figure."""
    overlay = tmp_path / "budget.yaml"
    overlay.write_text(f"server: {{max_inflight_mb: {BUDGET_MB}, max_concurrent_rpcs: 8}}\n")
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "models", "--listen", address, "--overlay", str(overlay)
                       ) as process:
        wait_serving(address, timeout=120, process=process)
        with grpc.insecure_channel(address, options=CHANNEL_OPTIONS) as channel:
            yield process, channel


def flood(channel: grpc.Channel, request: oip.ModelInferRequest, calls: int
          ) -> tuple[Counter[grpc.StatusCode], list[str]]:
    """`calls` copies of the request at once: their status codes, and the pushback of
    refusals for memory."""
    stub = oip_grpc.GRPCInferenceServiceStub(channel)
    pending = [stub.ModelInfer.future(request, timeout=120) for _ in range(calls)]
    codes: Counter[grpc.StatusCode] = Counter()
    pushback = []
    for call in pending:
        codes[call.code()] += 1
        if "data in flight" in (call.details() or ""):
            pushback += [v for k, v in call.trailing_metadata() or () if k == PUSHBACK_KEY]
    return codes, pushback


def encoded(data: bytes) -> oip.ModelInferRequest:
    tensor = np.empty(1, dtype=object)
    tensor[0] = data
    return infer_request("yolox-nano", {"images": tensor})


# 26 text lines of 48x1000 for the text-direction classifier: 15 MB, within the message
# limit; the network's intermediate tensors for it are many times that.
TENSOR = infer_request("text-direction", {"x": np.zeros((26, 3, 48, 1000), np.float32)})


@pytest.mark.parametrize("case", ["6000x6000 JPEG", "15 MB tensor"])
def test_calls_beyond_the_budget_are_refused_and_peak_memory_stays_bounded(
        served: tuple[subprocess.Popen[str], grpc.Channel], case: str) -> None:
    request_ = encoded(blank(*BIG)) if case.endswith("JPEG") else TENSOR
    process, channel = served
    stub = oip_grpc.GRPCInferenceServiceStub(channel)
    stub.ModelInfer(request_, timeout=120)  # alone: what one such call costs is the baseline
    # Receiving CALLS such messages costs memory before any call is admitted, budget or
    # not: the same flood to an unknown model measures that, so the growth below is the
    # work on what was received.
    unknown = oip.ModelInferRequest()
    unknown.CopyFrom(request_)
    unknown.model_name = "no-such-model"
    flood(channel, unknown, CALLS)
    before = peak_rss_mb(process.pid)
    codes, pushback = flood(channel, request_, CALLS)
    growth = peak_rss_mb(process.pid) - before
    assert set(codes) <= {grpc.StatusCode.OK, grpc.StatusCode.RESOURCE_EXHAUSTED}, codes
    assert codes[grpc.StatusCode.OK] >= 1 and pushback, codes
    assert all(int(ms) > 0 for ms in pushback)
    assert growth < MAX_GROWTH_MB, f"{case}: peak memory grew {growth:.0f} MB ({codes})"
    assert stub.ModelInfer(encoded(image("person.jpg").read_bytes()), timeout=30).outputs


def test_a_stream_frame_beyond_the_budget_is_refused_alone() -> None:
    """In the detector's DetectStream a frame that does not fit is refused with its own
    error, and the stream goes on."""
    with running_service("detector", {"server": {"max_inflight_mb": 150}}) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        big = common_pb2.Image(data=blank(*BIG), encoding="jpeg")  # needs 206 MB
        good = common_pb2.Image(data=image("person.jpg").read_bytes(), encoding="jpeg")
        frames = [detector_pb2.DetectRequest(image=img, frame_id=i, labels=["person"])
                  for i, img in enumerate([good, big, good], start=1)]
        responses = list(stub.DetectStream(iter(frames), timeout=60))
    assert [r.frame_id for r in responses] == [1, 2, 3]
    assert responses[1].error.code == grpc.StatusCode.INVALID_ARGUMENT.value[0]
    assert "more than the service's whole budget" in responses[1].error.message
    assert count(responses[0], "person") == count(responses[2], "person") == 1
