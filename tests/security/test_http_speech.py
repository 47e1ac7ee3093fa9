"""Hostile input on the speech service's POST /v1/audio/speech, against a real `oricf serve tts
--http-listen` process: fuzzed JSON bodies (every field drawn from hostile values, texts with
control characters, markup and lone UTF-16 surrogates among them), bytes that are not JSON
and 10 MB bodies. Every
answer is audio or a client error in OpenAI's shape, never a 500; memory stays bounded; the
service speaks normally afterwards."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.support.fuzzing import examples
from tests.support.openai_http import HttpService, health, http_service, overlay, rss_mb

CLIENT_ERRORS = {400, 404, 413, 429}
MAX_GROWTH_MB = 300
SERVER = {"max_concurrent_rpcs": 4, "http": {"request_timeout_s": 5}}

HOSTILE = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70),
                    st.floats(), st.text(max_size=60),
                    st.sampled_from(["joe", "espeak", "wav", "pcm", "oricf-tts", "mp3",
                                     "<speak>hi</speak>", "[[h@loU]]", "a\x00b", "x" * 5000,
                                     "1st 2.5 m 50% $3 10:30 -7 1,000,000", "\u202e\u200b",
                                     "1" + ",000" * 400, "9" * 60 + "th",
                                     "\ud800", "Hello \udfff world", "\ud83d"]))
VALUES = st.recursive(HOSTILE, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=12), inner, max_size=3)),
    max_leaves=8)
FIELDS = {"model": VALUES, "input": VALUES, "voice": VALUES, "response_format": VALUES,
          "speed": VALUES, "instructions": VALUES, "stream_format": VALUES, "extra": VALUES}


@pytest.fixture(scope="module")
def limited_tts(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    folder = tmp_path_factory.mktemp("tts")
    with http_service("tts", "--overlay", overlay(folder, {"server": SERVER})) as service:
        yield service


def url(service: HttpService) -> str:
    return f"{service.base_url}/v1/audio/speech"


def assert_answered(response: httpx.Response) -> None:
    if response.status_code == 200:
        assert response.headers["content-type"] in ("audio/wav", "audio/pcm")
        return
    assert response.status_code in CLIENT_ERRORS, (response.status_code, response.text)
    error = response.json()["error"]
    assert set(error) == {"message", "type", "param", "code"} and error["message"]
    assert "Traceback" not in response.text


def still_speaking(service: HttpService) -> None:
    assert health(service).status_code == 200
    response = httpx.post(url(service), json={"input": "Still here.", "voice": "espeak"},
                          timeout=30)
    assert response.status_code == 200 and len(response.content) > 1000


@settings(max_examples=examples(200), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.fixed_dictionaries({}, optional=FIELDS))
def test_fuzzed_bodies_get_audio_or_clear_errors(limited_tts: HttpService,
                                                 body: dict[str, Any]) -> None:
    try:  # JSON's escapes carry lone surrogates too (httpx's json= cannot encode them)
        content = json.dumps(body, allow_nan=False).encode()
    except ValueError:  # a float hypothesis drew that JSON cannot carry (NaN, infinity)
        content = repr(body).encode("utf-8", "backslashreplace")
    response = httpx.post(url(limited_tts), content=content, timeout=60,
                          headers={"Content-Type": "application/json"})
    assert_answered(response)
    assert limited_tts.process.poll() is None


@settings(max_examples=examples(60), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300))
def test_bytes_that_are_not_json_are_400(limited_tts: HttpService, body: bytes) -> None:
    response = httpx.post(url(limited_tts), content=body, timeout=30)
    assert_answered(response)
    assert response.status_code != 200


@pytest.mark.parametrize(("body", "field"), [
    ({"input": "Hello \ud800 world", "voice": "espeak"}, "input"),
    ({"input": "\udfff", "voice": "espeak"}, "input"),
    ({"input": "Hello.", "voice": "espeak\ud800"}, "voice"),
    ({"input": "Hello.", "voice": "espeak", "model": "\ud83d"}, "model"),
    ({"input": "Hello.", "voice": "espeak", "response_format": "wav\udc00"},
     "response_format"),
    ({"input": "Hello.", "voice": "espeak", "instructions": "\ud800"}, "instructions"),
])
def test_lone_surrogates_are_400_naming_the_field(limited_tts: HttpService, body: dict[str, Any],
                                                  field: str) -> None:
    response = httpx.post(url(limited_tts), content=json.dumps(body), timeout=30,
                          headers={"Content-Type": "application/json"})
    assert response.status_code == 400, response.text
    assert_answered(response)
    error = response.json()["error"]
    assert error["param"] == field and "surrogate" in error["message"]


def test_ten_megabyte_bodies_are_refused_with_bounded_memory(limited_tts: HttpService) -> None:
    before = rss_mb(limited_tts.process.pid)
    big = b'{"input": "' + b"a " * (5 * 1024 * 1024) + b'"}'
    for _ in range(3):
        response = httpx.post(url(limited_tts), content=big, timeout=30)
        assert response.status_code == 413, response.text
    assert rss_mb(limited_tts.process.pid) - before < MAX_GROWTH_MB
    still_speaking(limited_tts)


def test_after_the_fuzzing_it_still_speaks(limited_tts: HttpService) -> None:
    still_speaking(limited_tts)
