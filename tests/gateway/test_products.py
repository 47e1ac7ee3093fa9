"""Data products: latest value, age, staleness; context never passes stale as current."""

from __future__ import annotations

import pytest

from oricf.gateway.calls import generate_request
from oricf.gateway.config import GenerateCall
from oricf.gateway.products import ProductStore


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
    assert store.context(["people_count"], "omit") == {}  # never written
    store.put("people_count", 3)
    clock.now += 1.5
    assert store.context(["people_count"], "omit") == {"people_count": "3",
                                                        "people_count_age_s": "1.5"}
    clock.now += 10.5
    assert store.context(["people_count"], "omit") == {}
    assert store.context(["people_count"], "mark") == {
        "people_count": "3", "people_count_age_s": "12.0", "people_count_stale": "true"}


def test_generate_request_carries_fresh_context_only(store: ProductStore, clock: Clock) -> None:
    call = GenerateCall.model_validate({
        "service": "llm", "method": "Generate", "prompt": "{text}", "max_tokens": 24,
        "temperature": 0.0, "context": {"products": ["people_count"]}})
    store.put("people_count", 4)
    fresh = generate_request({"text": " How many people? "}, call, store)
    assert (fresh.prompt, dict(fresh.context), fresh.max_tokens) == (
        "How many people?", {"people_count": "4", "people_count_age_s": "0.0"}, 24)
    assert fresh.HasField("temperature") and fresh.temperature == 0.0
    clock.now += 6.0
    assert dict(generate_request({"text": "How many?"}, call, store).context) == {}


def test_listeners_get_every_new_value(store: ProductStore) -> None:
    seen: list[object] = []
    store.subscribe("people_count", seen.append)
    store.put("people_count", 1)
    store.put("people_count", 2)
    assert seen == [1, 2]
    with pytest.raises(KeyError, match="never declared"):
        store.put("transcript", "hello")
