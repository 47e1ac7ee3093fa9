"""`oricf serve models` with dynamic batching: Open Inference Protocol requests of different
callers share one run of a declared model, each caller gets its own rows back, and requests
that cannot be joined (other image sizes) run apart. As in the detector's tests, the delay
is the longest and the batch size the number of requests sent, so a batch forms because the
requests are there, not because this machine is fast."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import grpc
import numpy as np
import pytest

from oricf.errors import ConfigError
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.support.data import video_frames
from tests.support.metrics import scrape
from tests.support.services import RunningService, running_service, service_config

BATCH = 4
HOLD = {"max_batch_size": BATCH, "max_queue_delay_ms": 10_000}
WAIT_S = 60


@pytest.fixture(scope="module")
def unbatched(models: RunningService) -> RunningService:
    """The session's models service: its shipped settings batch nothing."""
    return models


@pytest.fixture(scope="module")
def batched() -> Iterator[RunningService]:
    overrides = {"batching": {"yolox-nano": HOLD, "text-direction": HOLD},
                 "server": {"metrics": {"listen": "127.0.0.1:0"}}}
    with running_service("models", overrides) as service:
        yield service


def infer_all(service: RunningService, requests: list[oip.ModelInferRequest]
              ) -> list[dict[str, np.ndarray]]:
    """Each request from a channel of its own, all at once."""
    channels = [grpc.insecure_channel(service.address) for _ in requests]
    try:
        with ThreadPoolExecutor(len(requests)) as pool:
            responses = pool.map(
                lambda pair: oip_grpc.GRPCInferenceServiceStub(pair[0]).ModelInfer(
                    pair[1], timeout=WAIT_S), zip(channels, requests, strict=True))
            return [response_outputs(r) for r in responses]
    finally:
        for channel in channels:
            channel.close()


def batch_sizes(service: RunningService, model: str) -> tuple[float, float]:
    server = service.host.metrics_server
    assert server is not None
    found = scrape(f"http://127.0.0.1:{server.port}/metrics")
    labels = {"service": "models", "batcher": f"models/{model}"}
    return (found.value("oricf_batch_size_count", **labels),
            found.value("oricf_batch_size_sum", **labels))


def one_batch_and_alone(batched: RunningService, unbatched: RunningService, model: str,
                        requests: list) -> list[tuple[dict, dict]]:
    """The requests sent at once to the batching service, checked to run as one batch of
    BATCH; each answer beside the unbatched service's answer to the same request."""
    before = batch_sizes(batched, model)
    answers = infer_all(batched, requests)
    assert batch_sizes(batched, model) == (before[0] + 1, before[1] + BATCH)
    alone = oip_grpc.GRPCInferenceServiceStub(unbatched.channel)
    return [(got, response_outputs(alone.ModelInfer(request, timeout=WAIT_S)))
            for request, got in zip(requests, answers, strict=True)]


def test_detector_frames_of_four_callers_run_as_one_batch(
        batched: RunningService, unbatched: RunningService) -> None:
    model = unbatched.host.slot.peek().get("yolox-nano")
    requests = [infer_request("yolox-nano", model.prepare(f).feeds)
                for f in video_frames([0, 200, 400, 600])]
    for got, want in one_batch_and_alone(batched, unbatched, "yolox-nano", requests):
        assert got["output"].shape == (1, 3549, 85)
        np.testing.assert_allclose(got["output"], want["output"], rtol=0, atol=1e-3)


def test_requests_of_other_sizes_share_a_batch_but_not_a_run(
        batched: RunningService, unbatched: RunningService) -> None:
    # The text-direction classifier takes any height and width: two widths, two runs.
    first = np.random.default_rng(0).uniform(-1, 1, (1, 3, 48, 192)).astype(np.float32)
    second = np.random.default_rng(1).uniform(-1, 1, (1, 3, 48, 96)).astype(np.float32)
    requests = [infer_request("text-direction", {"x": x})
                for x in (first, second, first[:, :, :, ::-1].copy(), second * 0.5)]
    for got, want in one_batch_and_alone(batched, unbatched, "text-direction", requests):
        (name,) = want
        np.testing.assert_allclose(got[name], want[name], rtol=0, atol=1e-5)


def test_a_request_larger_than_a_batch_is_refused(batched: RunningService) -> None:
    stub = oip_grpc.GRPCInferenceServiceStub(batched.channel)
    rows = np.zeros((BATCH + 1, 3, 48, 192), np.float32)
    with pytest.raises(grpc.RpcError) as error:
        stub.ModelInfer(infer_request("text-direction", {"x": rows}), timeout=WAIT_S)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert f"batches 1 to {BATCH}" in (error.value.details() or "")


def test_batching_an_unknown_model_is_refused_at_start() -> None:
    with pytest.raises(ConfigError, match="batching: no model 'nope'"), \
            running_service("models", {"batching": {"nope": HOLD}}):
        pass


def test_batching_keys_are_checked() -> None:
    with pytest.raises(ConfigError, match="max_batch_size"):
        service_config("detector", {"batching": {"max_batch_size": 0}})
    with pytest.raises(ConfigError, match="max_delay"):
        service_config("detector", {"batching": {"max_delay": 5}})
