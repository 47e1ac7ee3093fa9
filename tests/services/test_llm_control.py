"""Cancellation, deadlines and the wait queue, on long generations of the real model.

The service here uses a plain prompt with no stop sequence ("Count from 1 to 500: 1, 2,"),
so the model counts on for as many tokens as it is allowed: long enough to cancel.
"""

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import grpc
import pytest

from oricf.services.llm.model import LlamaModel
from oricf.v1 import language_pb2, language_pb2_grpc
from tests.support.services import RunningService, running_service

LONG = 256              # the service's max_tokens_limit: several seconds of counting
WAIT_TIMEOUT_S = 1.0
COUNTING_PROMPT = """\
format:
  header: ""
  turn: "{question}"
  answer: "{answer}"
  stop: []
"""
QUESTION = "Count from 1 to 500: 1, 2, 3, 4,"


def counting_service(folder: Path) -> dict[str, object]:
    prompt = folder / "counting.yaml"
    prompt.write_text(COUNTING_PROMPT)
    return {"prompts": {"gemma3-270m": str(prompt)},
            "queue": {"max_waiting": 1, "wait_timeout_s": WAIT_TIMEOUT_S}}


@pytest.fixture(scope="module")
def llm_counting(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningService]:
    with running_service("llm", counting_service(tmp_path_factory.mktemp("p"))) as service:
        yield service


@pytest.fixture
def stub(llm_counting: RunningService) -> language_pb2_grpc.LanguageModelStub:
    return language_pb2_grpc.LanguageModelStub(llm_counting.channel)


@pytest.fixture
def model(llm_counting: RunningService) -> Iterator[LlamaModel]:
    model: LlamaModel = llm_counting.host.slot.peek()
    wait_until(lambda: not model.gate.busy and model.gate.waiting == 0)
    yield model
    wait_until(lambda: not model.gate.busy and model.gate.waiting == 0)


def wait_until(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    give_up = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < give_up, "condition not reached in time"
        time.sleep(0.01)


def long_request(max_tokens: int = LONG) -> language_pb2.GenerateRequest:
    return language_pb2.GenerateRequest(prompt=QUESTION, max_tokens=max_tokens)


def test_the_counting_prompt_really_runs_long(stub: language_pb2_grpc.LanguageModelStub) -> None:
    answer = stub.Generate(long_request(40), timeout=30)
    assert answer.finish_reason == "length" and answer.completion_tokens == 40
    assert answer.text.startswith("5")


def test_cancelling_a_stream_stops_generation(stub: language_pb2_grpc.LanguageModelStub,
                                              model: LlamaModel) -> None:
    before = model.stats.completion_tokens
    stream = stub.GenerateStream(long_request(), timeout=60)
    received = [next(stream).text for _ in range(3)]
    stream.cancel()
    wait_until(lambda: not model.gate.busy)
    # Closed between chunks (abandoned) or stopped by the between-tokens check (Cancelled).
    assert model.stats.last_finish_reason in ("abandoned", "Cancelled")
    # Tokens made after the client left: the few already sent but not yet read (gRPC
    # buffers them), not the 250 it asked for.
    assert model.stats.completion_tokens - before <= len(received) + 20
    # The model is free for the next caller, with no one ahead of it.
    assert not model.gate.busy and model.gate.waiting == 0
    answer = stub.Generate(long_request(4), timeout=30)
    assert answer.completion_tokens == 4 and model.stats.last_finish_reason == "length"


def test_a_unary_caller_going_away_stops_generation(stub: language_pb2_grpc.LanguageModelStub,
                                                    model: LlamaModel) -> None:
    call = stub.Generate.future(long_request(), timeout=60)
    wait_until(lambda: model.gate.busy)
    time.sleep(0.3)
    call.cancel()
    wait_until(lambda: not model.gate.busy)
    assert model.stats.last_finish_reason == "Cancelled"
    assert model.stats.last_completion_tokens < LONG


def test_a_deadline_stops_generation_and_frees_the_model(
        stub: language_pb2_grpc.LanguageModelStub, model: LlamaModel) -> None:
    with pytest.raises(grpc.RpcError) as caught:
        stub.Generate(long_request(), timeout=0.5)
    assert caught.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    wait_until(lambda: not model.gate.busy, timeout=2)
    assert model.stats.last_finish_reason in ("DeadlineExceeded", "Cancelled")
    assert model.stats.last_completion_tokens < LONG
    answer = stub.Generate(long_request(4), timeout=30)
    assert answer.completion_tokens == 4


def start_long_stream(stub: language_pb2_grpc.LanguageModelStub) -> grpc.Future:
    stream = stub.GenerateStream(long_request(), timeout=60)
    next(stream)  # generating now
    return stream


def test_beyond_the_queue_limit_is_resource_exhausted(
        stub: language_pb2_grpc.LanguageModelStub, model: LlamaModel) -> None:
    running = start_long_stream(stub)
    waiting = stub.Generate.future(long_request(4), timeout=60)
    wait_until(lambda: model.gate.waiting == 1)
    with pytest.raises(grpc.RpcError) as caught:
        stub.Generate(long_request(4), timeout=30)
    assert caught.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert "queue limit 1" in caught.value.details()
    running.cancel()
    answer = waiting.result(timeout=30)  # the waiting caller gets its turn
    assert answer.completion_tokens == 4 and answer.timings.queue_ms > 0


def test_waiting_too_long_is_resource_exhausted(stub: language_pb2_grpc.LanguageModelStub,
                                                model: LlamaModel) -> None:
    running = start_long_stream(stub)
    started = time.perf_counter()
    with pytest.raises(grpc.RpcError) as caught:
        stub.Generate(long_request(4), timeout=30)
    waited = time.perf_counter() - started
    running.cancel()
    assert caught.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert "queue wait timeout" in caught.value.details()
    assert WAIT_TIMEOUT_S <= waited < WAIT_TIMEOUT_S + 2


def test_a_waiting_caller_who_leaves_frees_its_place(
        stub: language_pb2_grpc.LanguageModelStub, model: LlamaModel) -> None:
    running = start_long_stream(stub)
    waiting = stub.Generate.future(long_request(4), timeout=60)
    wait_until(lambda: model.gate.waiting == 1)
    waiting.cancel()
    wait_until(lambda: model.gate.waiting == 0, timeout=2)
    assert model.gate.busy  # the running generation was not disturbed
    running.cancel()


def test_shutdown_stops_a_running_generation(tmp_path: Path) -> None:
    with running_service("llm", counting_service(tmp_path)) as service:
        stub = language_pb2_grpc.LanguageModelStub(service.channel)
        model: LlamaModel = service.host.slot.peek()
        stream = start_long_stream(stub)
        started = time.perf_counter()
        service.host.stop(grace=0.2)
        stopped_in = time.perf_counter() - started
        with pytest.raises(grpc.RpcError) as caught:
            list(stream)
        assert caught.value.code() in (grpc.StatusCode.CANCELLED, grpc.StatusCode.UNAVAILABLE)
        assert stopped_in < 3
        assert model.stats.last_completion_tokens < LONG
        assert not model.loaded  # the weights were freed after the generation ended
