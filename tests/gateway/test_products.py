"""Data products: latest value, age, staleness; as call context they go as typed facts
(oricf.v1.Fact), and a stale one is never passed as current."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, PipelineConfig, parse_pipeline
from oricf.gateway.methods.generate import GenerateCall, fact, generate_request
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.products import ProductStore, Reading
from oricf.gateway.values import Frame, Record
from oricf.services.llm.domain import Fact, GenerationRequest, StillWanted
from oricf.v1 import common_pb2
from tests.support.data import video_frames
from tests.support.services import RunningService


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture()
def clock() -> Clock:
    return Clock()


@pytest.fixture()
def store(clock: Clock) -> ProductStore:
    store = ProductStore(clock)
    store.declare("people_count", 5.0)
    return store


def test_readings_age_and_go_stale(store: ProductStore, clock: Clock) -> None:
    assert store.read("people_count") is None
    store.put("people_count", 3)
    clock.now += 4.0
    reading = store.read("people_count")
    assert reading is not None and (reading.value, reading.age_s, reading.stale) == (3, 4.0, False)
    clock.now += 2.0
    reading = store.read("people_count")
    assert reading is not None and reading.stale


def test_context_leaves_out_or_marks_stale_values(store: ProductStore, clock: Clock) -> None:
    assert store.context(["people_count"], "omit") == []  # never written
    store.put("people_count", 3)
    clock.now += 1.5
    assert store.context(["people_count"], "omit") == [Reading("people_count", 3, 1.5, 5.0)]
    clock.now += 10.5
    assert store.context(["people_count"], "omit") == []
    marked = store.context(["people_count"], "mark")
    assert marked == [Reading("people_count", 3, 12.0, 5.0)] and marked[0].stale


def generate_call(stale: str = "omit") -> GenerateCall:
    return GenerateCall.model_validate({
        "service": "llm", "method": "Generate", "prompt": "{text}", "max_tokens": 24,
        "temperature": 0.0, "context": {"products": ["people_count"], "stale": stale}})


def test_generate_request_carries_fresh_typed_facts_only(store: ProductStore,
                                                         clock: Clock) -> None:
    call = generate_call()
    store.put("people_count", 4)
    fresh = generate_request({"text": " How many people? "}, call, store)
    assert (fresh.prompt, fresh.max_tokens) == ("How many people?", 24)
    assert list(fresh.facts) == [common_pb2.Fact(name="people_count", integer=4, age_s=0.0)]
    assert fresh.facts[0].HasField("age_s")  # age 0 is sent, not left unknown
    assert fresh.HasField("temperature") and fresh.temperature == 0.0
    clock.now += 6.0
    assert list(generate_request({"text": "How many?"}, call, store).facts) == []


def test_generate_request_marks_a_stale_fact(store: ProductStore, clock: Clock) -> None:
    store.put("people_count", 4)
    clock.now += 6.0
    request = generate_request({"text": "How many?"}, generate_call("mark"), store)
    assert list(request.facts) == [
        common_pb2.Fact(name="people_count", integer=4, age_s=6.0, stale=True)]


@pytest.mark.parametrize(("value", "typed"), [
    (3, {"integer": 3}),
    (np.int64(7), {"integer": 7}),
    (2**70, {"number": float(2**70)}),
    (0.75, {"number": 0.75}),
    (np.float32(0.5), {"number": 0.5}),
    (True, {"flag": True}),
    (np.bool_(False), {"flag": False}),
    ("a person waves", {"text": "a person waves"}),
    ({"person": 2, "dog": 1}, {"text": '{"person": 2, "dog": 1}'}),
    (None, {}),
    (math.nan, {}),
], ids=["int", "numpy-int", "huge-int", "float", "numpy-float", "bool", "numpy-bool", "str",
        "dict", "none", "nan"])
def test_each_value_goes_in_its_own_type(value: Any, typed: dict[str, Any]) -> None:
    sent = fact(Reading("thing", value, 1.25, 5.0))
    assert sent == common_pb2.Fact(name="thing", age_s=1.25, **typed)


def test_listeners_get_every_new_value(store: ProductStore) -> None:
    seen: list[object] = []
    store.subscribe("people_count", seen.append)
    store.put("people_count", 1)
    store.put("people_count", 2)
    assert seen == [1, 2]
    with pytest.raises(KeyError, match="never declared"):
        store.put("transcript", "hello")


# The whole path: a real detector counts people in a real frame, the data product goes
# through a real Pipeline to the real language service as a typed fact.

QUESTION = "How many people do you see?"


@pytest.fixture(scope="module")
def services(detector: RunningService, llm: RunningService
             ) -> tuple[RunningService, RunningService]:
    return detector, llm


class Answers(Emitter):
    def __init__(self) -> None:
        self.sent: list[str] = []

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        if output.topic == "/answer":
            self.sent.append(value)


def asking_pipeline(detector: str, llm: str, stale: str) -> PipelineConfig:
    return parse_pipeline({
        "endpoints": {"detector": {"address": detector},
                      "llm": {"address": llm, "deadline_ms": 30000}},
        "routes": {
            "people": {
                "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
                "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
                "post": [{"count": {"label": "person", "into": "count"}}],
                "outputs": [{"product": "people_count", "from": "count", "max_age_s": 5}]},
            "ask": {
                "input": {"topic": "/question", "type": "std_msgs/String"},
                "call": {"service": "llm", "method": "Generate", "prompt": "{text}",
                         "max_tokens": 32,
                         "context": {"products": ["people_count"], "stale": stale}},
                "outputs": [{"topic": "/answer", "type": "std_msgs/String",
                             "from": "answer"}]}}}, "test pipeline")


def received_facts(llm: RunningService, monkeypatch: pytest.MonkeyPatch
                   ) -> list[tuple[Fact, ...]]:
    """The facts of each request as the language service received them off the wire."""
    model = llm.host.slot.peek()
    original = model.generate
    seen: list[tuple[Fact, ...]] = []

    def spy(request: GenerationRequest, still_wanted: StillWanted) -> Any:
        seen.append(request.facts)
        return original(request, still_wanted)

    monkeypatch.setattr(model, "generate", spy)
    return seen


def ask(pipeline: Pipeline) -> None:
    pipeline.submit("ask", lambda: {"text": QUESTION})
    assert pipeline.idle(60)


@pytest.mark.parametrize("stale", ["mark", "omit"])
def test_the_gateway_sends_the_count_as_a_typed_fact(
        services: tuple[RunningService, RunningService], monkeypatch: pytest.MonkeyPatch,
        clock: Clock, stale: str) -> None:
    detector, llm = services
    seen = received_facts(llm, monkeypatch)
    answers = Answers()
    pipeline = Pipeline(asking_pipeline(detector.address, llm.address, stale), answers,
                        ProductStore(clock))
    pipeline.start()
    try:
        frame = Frame.from_pixels(video_frames([0])[0])
        pipeline.submit("people", lambda: {"image": frame})
        assert pipeline.idle(30)
        count = pipeline.products.read("people_count").value  # type: ignore[union-attr]
        clock.now += 1.5
        ask(pipeline)
        clock.now += 10.0  # older than the product's max_age_s (5 s)
        ask(pipeline)
    finally:
        pipeline.stop()
    assert count >= 1 and pipeline.routes["ask"].stats.ok == 2
    current = Fact("people_count", count, 1.5, False)
    marked = Fact("people_count", count, 11.5, True)
    assert seen == [(current,), (marked,) if stale == "mark" else ()]
    assert isinstance(seen[0][0].value, int)  # an integer on the wire, not a string
    fresh_answer, stale_answer = answers.sent
    assert str(count) in fresh_answer, fresh_answer
    assert str(count) not in stale_answer and "know" in stale_answer, stale_answer
