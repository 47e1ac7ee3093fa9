"""The language model service with its shipped config: real model, real gRPC, real grpcurl."""

import gc
import json
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

import grpc
import llama_cpp
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.services.llm.model import LlamaModel
from oricf.store import ModelStore
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc
from tests.support.grpcurl import grpcurl, run_grpcurl
from tests.support.services import RunningService, running_service

DEADLINE_S = 30


@pytest.fixture
def stub(llm: RunningService) -> language_pb2_grpc.LanguageModelStub:
    return language_pb2_grpc.LanguageModelStub(llm.channel)


def model_of(service: RunningService) -> LlamaModel:
    model: LlamaModel = service.host.slot.peek()
    return model


def people(count: int | None = None, **fields: object) -> common_pb2.Fact:
    """The people count as a typed fact, as the gateway sends it (None: no value)."""
    return common_pb2.Fact(name="people_count", integer=count, **fields)


def generate(stub: language_pb2_grpc.LanguageModelStub, prompt: str,
             **fields: object) -> language_pb2.GenerateResponse:
    request = language_pb2.GenerateRequest(prompt=prompt, **fields)
    response: language_pb2.GenerateResponse = stub.Generate(request, timeout=DEADLINE_S)
    return response


def test_the_answer_states_the_people_count(stub: language_pb2_grpc.LanguageModelStub) -> None:
    answer = generate(stub, "How many people do you see?", facts=[people(3, age_s=0.4)])
    assert "3" in answer.text, answer.text
    assert answer.finish_reason == "stop"
    assert "\n" not in answer.text and answer.text == answer.text.strip()
    assert 0 < answer.completion_tokens < 20
    assert answer.prompt_tokens > 100  # the template's system text and examples
    t = answer.timings
    assert 0 < t.first_token_ms <= t.total_ms
    assert 0 < t.inference_ms <= t.total_ms


@pytest.mark.parametrize(("count", "question", "expected"), [
    (0, "Is anyone there?", "no one"),
    (1, "Are you alone?", "1 person"),
    (12, "How many humans are in the room?", "12"),
])
def test_other_counts_and_phrasings(stub: language_pb2_grpc.LanguageModelStub, count: int,
                                    question: str, expected: str) -> None:
    answer = generate(stub, question, facts=[people(count)])
    assert expected in answer.text.lower(), answer.text


@pytest.mark.parametrize("facts", [
    [],
    [people()],
    [common_pb2.Fact(name="people_count", text="")],
    [people(3, age_s=2.0, stale=True)],
    [people(3, age_s=60.0)],
], ids=["absent", "no-value", "empty-text", "marked-stale", "too-old"])
def test_an_unknown_or_stale_count_is_not_stated(stub: language_pb2_grpc.LanguageModelStub,
                                                 facts: list[common_pb2.Fact]) -> None:
    answer = generate(stub, "How many people do you see?", facts=facts)
    assert "know" in answer.text, answer.text
    assert not any(ch.isdigit() for ch in answer.text), answer.text


def test_a_recent_count_is_used(stub: language_pb2_grpc.LanguageModelStub) -> None:
    answer = generate(stub, "How many people do you see?",
                      facts=[people(5, age_s=1.5)])
    assert "5" in answer.text, answer.text


def test_stream_yields_the_answer_in_several_chunks(
        stub: language_pb2_grpc.LanguageModelStub) -> None:
    request = language_pb2.GenerateRequest(prompt="How many people do you see?",
                                           facts=[people(7)])
    messages = list(stub.GenerateStream(request, timeout=DEADLINE_S))
    assert len([m for m in messages if m.text]) >= 3
    assert all(not m.finish_reason for m in messages[:-1])
    last = messages[-1]
    assert last.finish_reason == "stop"
    assert last.completion_tokens >= 3 and last.prompt_tokens > 100
    assert 0 < last.timings.first_token_ms < last.timings.total_ms
    streamed = "".join(m.text for m in messages)
    assert streamed == generate(stub, request.prompt, facts=request.facts).text
    assert "7" in streamed


def test_the_fixed_prompt_prefix_is_reused(llm: RunningService,
                                           stub: language_pb2_grpc.LanguageModelStub) -> None:
    model = model_of(llm)
    prefix_tokens = len(model._tokenize(model.renderer.prefix, add_bos=True))
    generate(stub, "Is anyone there?", facts=[people(2)])
    generate(stub, "How many visitors are there?", facts=[people(8)])
    assert model.stats.last_cached_tokens >= prefix_tokens - 1
    assert model.stats.last_prompt_tokens - model.stats.last_cached_tokens < 30


def test_the_model_is_free_as_soon_as_an_answer_returns(
        llm: RunningService, stub: language_pb2_grpc.LanguageModelStub) -> None:
    generate(stub, "Is anyone there?", facts=[people(1)])
    assert not model_of(llm).gate.busy


def unfreed_samplers() -> int:
    """llama.cpp sampler chains in this process whose native memory is not yet freed."""
    from llama_cpp._internals import LlamaSampler

    return sum(isinstance(o, LlamaSampler) and o.sampler is not None for o in gc.get_objects())


def test_each_generation_frees_its_sampler_chain_when_it_ends(
        stub: language_pb2_grpc.LanguageModelStub) -> None:
    # A chain (buffers the size of the vocabulary) left in a reference cycle waits for the
    # garbage collector's full pass, rare in a long-running service: with the collector
    # held off, as between two such passes, every request would leave one behind.
    gc.collect()
    before = unfreed_samplers()
    gc.disable()
    try:
        for count in range(6):
            generate(stub, "How many people do you see?", facts=[people(count)], max_tokens=4)
            list(stub.GenerateStream(language_pb2.GenerateRequest(
                prompt="Is anyone there?", facts=[people(count)]), timeout=DEADLINE_S))
        assert unfreed_samplers() <= before
    finally:
        gc.enable()


def wait_until(condition: Callable[[], bool], timeout: float = DEADLINE_S) -> None:
    give_up = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < give_up, "condition not reached in time"
        time.sleep(0.005)


def test_concurrent_callers_are_served_one_at_a_time(
        llm: RunningService, stub: language_pb2_grpc.LanguageModelStub) -> None:
    gate = model_of(llm).gate
    request = language_pb2.GenerateRequest(prompt="Is anyone there?")
    with gate.turn(lambda: None):  # as a generation in progress holds the model
        calls = [stub.Generate.future(request, timeout=DEADLINE_S) for _ in range(3)]
        wait_until(lambda: gate.waiting == 3)  # all wait (the shipped queue holds 4)
        assert not any(call.done() for call in calls)
    wait_until(lambda: gate.busy and gate.waiting == 2)  # then one runs, two wait
    answers = [call.result() for call in calls]
    assert len({a.text for a in answers}) == 1 and answers[0].finish_reason == "stop"


def test_max_tokens_cuts_the_answer(stub: language_pb2_grpc.LanguageModelStub) -> None:
    answer = generate(stub, "How many people do you see?", facts=[people(3)], max_tokens=2)
    assert answer.finish_reason == "length"
    assert answer.completion_tokens == 2


def test_a_request_stop_sequence_ends_the_answer(
        stub: language_pb2_grpc.LanguageModelStub) -> None:
    full = generate(stub, "How many people do you see?", facts=[people(4)])
    assert "people" in full.text
    cut = generate(stub, "How many people do you see?", facts=[people(4)], stop=["people"])
    assert cut.finish_reason == "stop"
    assert cut.text == full.text[:full.text.index("people")]  # "I see 4 "


@contextmanager
def sampler_seed(service: RunningService, seed: int) -> Iterator[None]:
    """llama.cpp seeds each generation's sampler with this (by default a random seed each
    time), so sampled answers repeat and the test cannot fail by chance."""
    llm = model_of(service)._llm
    llm.set_seed(seed)
    try:
        yield
    finally:
        llm.set_seed(llama_cpp.LLAMA_DEFAULT_SEED)


def answers_by_seed(service: RunningService, stub: language_pb2_grpc.LanguageModelStub,
                    seeds: Sequence[int], **fields: object) -> list[str]:
    answers = []
    for seed in seeds:
        with sampler_seed(service, seed):
            answers.append(generate(stub, "Tell me about yourself.", **fields).text)
    return answers


def test_the_request_temperature_reaches_the_sampler(
        llm: RunningService, stub: language_pb2_grpc.LanguageModelStub) -> None:
    seeds = [1, 2, 3, 4]
    # The shipped default (0) and an explicit 0 are greedy: the seed changes nothing.
    greedy = answers_by_seed(llm, stub, seeds) + answers_by_seed(llm, stub, seeds,
                                                                 temperature=0.0)
    assert len(set(greedy)) == 1, greedy
    # Temperature 2 samples: each seed draws its own answer, and the same seed the same one.
    hot = answers_by_seed(llm, stub, seeds, temperature=2.0)
    assert len(set(hot)) >= 3, hot
    assert answers_by_seed(llm, stub, seeds[:1], temperature=2.0) == hot[:1]


def test_get_model_info(stub: language_pb2_grpc.LanguageModelStub) -> None:
    info = stub.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=DEADLINE_S)
    entry = ModelStore().entry("gemma3-270m")
    assert info.service == "llm"
    assert info.model == "gemma3-270m"
    assert info.runtime.startswith("llama.cpp (llama-cpp-python 0.3.")
    assert info.sha256 == entry.files[0].sha256
    assert info.license == entry.license
    assert info.parameters["threads"] == "1"
    assert info.parameters["prompt"] == "gemma3-270m.yaml"
    assert info.load_seconds > 0


def test_health_is_serving(llm: RunningService) -> None:
    health = health_pb2_grpc.HealthStub(llm.channel)
    for service in ("", "oricf.v1.LanguageModel"):
        answer = health.Check(health_pb2.HealthCheckRequest(service=service), timeout=5)
        assert answer.status == health_pb2.HealthCheckResponse.SERVING


def test_grpcurl_lists_the_service(llm: RunningService) -> None:
    services = grpcurl(llm.address, "list").split()
    assert {"oricf.v1.LanguageModel", "grpc.health.v1.Health"} <= set(services)
    methods = grpcurl(llm.address, "list", "oricf.v1.LanguageModel").split()
    assert "oricf.v1.LanguageModel.Generate" in methods


def test_grpcurl_generate(llm: RunningService) -> None:
    body = json.dumps({"prompt": "How many people do you see?",
                       "facts": [{"name": "people_count", "integer": 3, "age_s": 1.2}]})
    answer = json.loads(grpcurl(llm.address, "oricf.v1.LanguageModel/Generate", data=body))
    assert "3" in answer["text"]
    assert answer["finish_reason"] == "stop"
    assert int(answer["completion_tokens"]) > 0


def test_grpcurl_a_stale_fact_is_not_stated(llm: RunningService) -> None:
    body = json.dumps({"prompt": "How many people do you see?",
                       "facts": [{"name": "people_count", "integer": 3, "stale": True}]})
    answer = json.loads(grpcurl(llm.address, "oricf.v1.LanguageModel/Generate", data=body))
    assert "know" in answer["text"] and "3" not in answer["text"], answer["text"]


def test_grpcurl_bad_input_is_invalid_argument(llm: RunningService) -> None:
    result = run_grpcurl(llm.address, "oricf.v1.LanguageModel/Generate", data='{"prompt": ""}')
    assert result.returncode != 0
    assert "InvalidArgument" in result.stderr and "prompt is empty" in result.stderr


def test_not_ready_before_the_model_loads() -> None:
    with running_service("llm", load=False) as service:
        stub = language_pb2_grpc.LanguageModelStub(service.channel)
        with pytest.raises(grpc.RpcError) as caught:
            stub.Generate(language_pb2.GenerateRequest(prompt="Hi"), timeout=DEADLINE_S)
        assert caught.value.code() == grpc.StatusCode.UNAVAILABLE
