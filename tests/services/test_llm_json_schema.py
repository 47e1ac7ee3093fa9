"""JSON Schemas that cost too much are refused before llama.cpp sees their grammar, against a
real `oricf serve llm --http-listen` process with the shipped model: a 400 naming the limit,
streamed or not, and the process (HTTP and gRPC) goes on serving; reasonable schemas are
still enforced, and the costliest schemas the limits let through are served with bounded
memory. The limits themselves are checked in test_llm_grammar.py."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import Any

import grpc
import httpx
import openai
import pytest

from oricf.v1 import language_pb2, language_pb2_grpc
from tests.services.schemas import look_alikes
from tests.support.openai_http import HttpService, client, http_service, overlay, rss_mb

MODEL = "gemma3-270m"
QUESTION = "How many people do you see? Answer in JSON."
FACTS = [{"name": "people_count", "integer": 4}]
# Decoding under the costliest accepted grammars is slower than usual, not unbounded: the
# client's timeout only keeps a broken service from hanging the test.
SLOW_ANSWER_S = 600
MAX_GROWTH_MB = 200


def string(pattern: str) -> dict[str, Any]:
    return {"type": "string", "pattern": pattern}


def response_format(schema: dict[str, Any]) -> dict[str, Any]:
    return {"type": "json_schema", "json_schema": {"name": "x", "schema": schema}}


@pytest.fixture(scope="module")
def llm_json_schema(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    folder = tmp_path_factory.mktemp("llm")
    limits = overlay(folder, {"generation": {"max_tokens_limit": 64}})
    with http_service("llm", "--overlay", limits) as service:
        yield service


@pytest.fixture
def api(llm_json_schema: HttpService) -> openai.OpenAI:
    return client(llm_json_schema, timeout=SLOW_ANSWER_S)


def ask(api: openai.OpenAI, schema: dict[str, Any], **options: Any) -> str:
    answer = api.chat.completions.create(
        model=MODEL, messages=[{"role": "user", "content": QUESTION}], temperature=0,
        response_format=response_format(schema),  # type: ignore[arg-type]
        extra_body={"facts": FACTS}, **options)
    return answer.choices[0].message.content or ""


def assert_serving(service: HttpService, api: openai.OpenAI) -> None:
    assert service.process.poll() is None, "the language service died"
    with grpc.insecure_channel(service.grpc_address) as channel:
        reply = language_pb2_grpc.LanguageModelStub(channel).Generate(
            language_pb2.GenerateRequest(prompt="How many people do you see?", facts=[]),
            timeout=60)
    assert reply.text
    assert json.loads(ask(api, {"type": "object", "properties": {"people": {
        "type": "integer"}}, "required": ["people"]})) == {"people": 4}


def test_a_counted_repetition_of_2000_is_400_and_both_apis_go_on(llm_json_schema: HttpService,
                                                       api: openai.OpenAI) -> None:
    schema = string("^a{0,2000}$")
    with pytest.raises(openai.BadRequestError) as error:
        ask(api, schema)
    assert "{0,2000} is over the limit of 256 repeats" in error.value.message
    assert_serving(llm_json_schema, api)


HOSTILE = [
    pytest.param(string("^a{0,2000}$"), "is over the limit of 256 repeats", id="a{0,2000}"),
    pytest.param(string("^a{0,100000000}$"), "is over the limit of 256 repeats",
                 id="a{0,10^8}"),
    pytest.param(string("^(a{0,50}){0,50}$"), "2,500 places; the limit is 256", id="nested"),
    pytest.param(string("^((a{0,8}){0,8}){0,8}$"), "512 places", id="three-deep"),
    pytest.param(string("^(a?){0,200}$"), "in over 32 ways", id="optional-run"),
    pytest.param(look_alikes(16), "in over 32 ways", id="look-alike-anyOf"),
    pytest.param(string("^\\x00$"), "the character NUL", id="NUL"),
    pytest.param(string("^[^\\x01-\\U0010FFFF]$"), "no character matches", id="empty-class"),
    pytest.param({"$defs": {"n": {"type": "array", "items": {"$ref": "#/$defs/n"}}},
                  "type": "object", "properties": {"x": {"$ref": "#/$defs/n"}}},
                 "recursive schemas are not supported", id="recursive"),
    pytest.param(string("^" + "(" * 2000 + "a" + ")" * 2000 + "$"), "nests too deeply",
                 id="deep-groups"),
]


@pytest.mark.parametrize("stream", [False, True])
@pytest.mark.parametrize(("schema", "says"), HOSTILE)
def test_costly_schemas_are_400_naming_the_limit(llm_json_schema: HttpService, api: openai.OpenAI,
                                                 schema: dict[str, Any], says: str,
                                                 stream: bool) -> None:
    body = {"model": MODEL, "stream": stream, "response_format": response_format(schema),
            "messages": [{"role": "user", "content": QUESTION}]}
    response = httpx.post(f"{llm_json_schema.base_url}/v1/chat/completions", json=body, timeout=60)
    assert response.status_code == 400, response.text
    error = response.json()["error"]
    assert says in error["message"] and error["type"] == "invalid_request_error"
    assert llm_json_schema.process.poll() is None


def test_a_reasonable_pattern_is_enforced(api: openai.OpenAI) -> None:
    answer = ask(api, {"type": "object", "properties": {"people": string("^[0-9]{1,3}$")},
                       "required": ["people"]})
    assert re.fullmatch(r"[0-9]{1,3}", json.loads(answer)["people"])


# The costliest kinds of grammar the default limits let through: repetitions at the
# repeat limit, optional items and look-alike alternatives just under the alternatives
# limit, and a grammar near the byte limit.
WORST_ALLOWED = [
    pytest.param({"type": "string", "maxLength": 256}, id="maxLength-256"),
    pytest.param(string("^[a-z]{0,256}$"), id="pattern-256"),
    pytest.param(string("^(a?){0,30}$"), id="optional-run-30"),
    pytest.param(look_alikes(2), id="look-alike-anyOf-2"),
    pytest.param({"enum": ["x" * 40 + str(i) for i in range(30)]}, id="enum-30-same-prefix"),
    pytest.param({"type": "object", "properties": {
        f"p{i}": {"type": "string", "maxLength": 256} for i in range(25)},
        "required": [f"p{i}" for i in range(25)]}, id="55KB-grammar"),
]


# Streamed, the same schemas are the long run's (the default run streams other schemas).
@pytest.mark.parametrize("stream", [False, pytest.param(True, marks=pytest.mark.long)])
@pytest.mark.parametrize("schema", WORST_ALLOWED)
def test_the_costliest_allowed_schemas_are_served(llm_json_schema: HttpService, api: openai.OpenAI,
                                                  schema: dict[str, Any],
                                                  stream: bool) -> None:
    before = rss_mb(llm_json_schema.process.pid)
    if stream:
        chunks = api.chat.completions.create(
            model=MODEL, messages=[{"role": "user", "content": QUESTION}], max_tokens=64,
            response_format=response_format(schema), stream=True)  # type: ignore[arg-type]
        finish = [chunk.choices[0].finish_reason for chunk in chunks if chunk.choices]
        assert finish[-1] in ("stop", "length")
    else:
        assert ask(api, schema, max_tokens=64)
    assert llm_json_schema.process.poll() is None
    assert rss_mb(llm_json_schema.process.pid) - before < MAX_GROWTH_MB
