"""The language service's OpenAI-compatible API through the official `openai` client, against
a real `oricf serve llm --http-listen` process with the shipped model; gRPC on the same
process for comparison."""

from __future__ import annotations

import json
import signal
import socket
from pathlib import Path

import grpc
import httpx
import jsonschema
import openai
import pytest

from oricf.services.local import local_service, service_config
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc
from tests.support.metrics import scrape
from tests.support.openai_http import HttpService, client, health, http_service

MODEL = "gemma3-270m"
QUESTION = "How many people do you see?"
FACTS = [{"name": "people_count", "integer": 4, "age_s": 0.5}]
COUNT_SCHEMA = {"type": "object", "properties": {"people": {"type": "integer"}},
                "required": ["people"], "additionalProperties": False}


@pytest.fixture
def api(llm_one_call: HttpService) -> openai.OpenAI:
    """The session's llm_one_call: one call at a time, so that the refusal test can fill the
    only slot."""
    return client(llm_one_call)


def ask(api: openai.OpenAI, question: str = QUESTION, **options: object) -> str:
    options.setdefault("extra_body", {"facts": FACTS})
    answer = api.chat.completions.create(
        model=MODEL, messages=[{"role": "user", "content": question}], temperature=0,
        seed=1, **options)  # type: ignore[call-overload]
    content: str = answer.choices[0].message.content or ""
    return content


def test_models_lists_the_served_model(api: openai.OpenAI) -> None:
    assert [model.id for model in api.models.list()] == [MODEL]


def test_a_plain_chat_is_answered(api: openai.OpenAI) -> None:
    answer = api.chat.completions.create(
        model=MODEL, messages=[{"role": "system", "content": "Be brief."},
                               {"role": "user", "content": "Hello, who are you?"}])
    choice = answer.choices[0]
    assert choice.message.role == "assistant" and choice.message.content
    assert choice.finish_reason in ("stop", "length")
    assert answer.usage is not None and answer.usage.prompt_tokens > 100
    assert answer.object == "chat.completion" and answer.id.startswith("chatcmpl-")


def test_facts_give_the_same_answer_as_grpc(llm_one_call: HttpService, api: openai.OpenAI) -> None:
    facts = [common_pb2.Fact(name="people_count", integer=4, age_s=0.5)]
    with grpc.insecure_channel(llm_one_call.grpc_address) as channel:
        over_grpc = language_pb2_grpc.LanguageModelStub(channel).Generate(
            language_pb2.GenerateRequest(prompt=QUESTION, facts=facts, temperature=0),
            timeout=30).text
    assert "4" in over_grpc
    assert ask(api) == over_grpc
    assert "4" not in ask(api, extra_body={"facts": []})  # the count comes from the fact


def test_a_streamed_answer_carries_usage_last(api: openai.OpenAI) -> None:
    stream = api.chat.completions.create(
        model=MODEL, messages=[{"role": "user", "content": QUESTION}], temperature=0,
        stream=True, stream_options={"include_usage": True}, extra_body={"facts": FACTS})
    chunks = list(stream)
    text = "".join(c.choices[0].delta.content or "" for c in chunks if c.choices)
    assert text == ask(api)
    assert chunks[0].choices[0].delta.role == "assistant"
    finishes = [c.choices[0].finish_reason for c in chunks if c.choices]
    assert finishes[-1] == "stop" and set(finishes[:-1]) == {None}
    usage = chunks[-1].usage
    assert not chunks[-1].choices and usage is not None
    assert usage.completion_tokens > 0
    assert usage.total_tokens == usage.prompt_tokens + usage.completion_tokens


def test_json_schema_answers_validate(api: openai.OpenAI) -> None:
    answer = ask(api, "How many people do you see? Answer in JSON.", response_format={
        "type": "json_schema", "json_schema": {"name": "count", "schema": COUNT_SCHEMA}})
    value = json.loads(answer)
    jsonschema.validate(value, COUNT_SCHEMA)
    assert value == {"people": 4}


def test_json_object_answers_are_json_until_cut(api: openai.OpenAI) -> None:
    """Any JSON object: the grammar keeps the text JSON; a small model may ramble on inside
    it until max_tokens cuts it (finish_reason "length", as OpenAI's API does)."""
    answer = api.chat.completions.create(
        model=MODEL, messages=[{"role": "user", "content": "Answer in JSON. Are you alone?"}],
        max_tokens=64, response_format={"type": "json_object"}, extra_body={"facts": FACTS})
    choice = answer.choices[0]
    text = choice.message.content or ""
    assert text.startswith("{")
    if choice.finish_reason == "stop":
        assert isinstance(json.loads(text), dict)
    else:
        assert choice.finish_reason == "length"


@pytest.mark.parametrize(("options", "status", "says"), [
    ({"temperature": 5}, 400, "temperature 5.0 is out of range"),
    ({"extra_body": {"facts": [{"name": "people_count", "integer": "many"}]}}, 400,
     "facts[0]"),
    ({"extra_body": {"facts": [{"name": "x", "integer": 1}, {"name": "x", "flag": True}]}},
     400, "fact 'x' is given twice"),
    ({"max_tokens": 100_000}, 400, "max_tokens 100000 is over this service's limit"),
    ({"n": 2}, 400, "one choice per request"),
    ({"response_format": {"type": "json_schema", "json_schema": {
        "name": "x", "schema": {"$ref": "https://example.com/schema.json"}}}}, 400,
     "only references inside the schema"),
    ({"model": "gpt-4o"}, 404, "this service serves 'gemma3-270m'"),
])
def test_bad_requests_are_refused_with_the_reason(api: openai.OpenAI, options: dict[str, object],
                                                  status: int, says: str) -> None:
    options = {"model": MODEL, "messages": [{"role": "user", "content": QUESTION}], **options}
    with pytest.raises(openai.APIStatusError) as error:
        api.chat.completions.create(**options)  # type: ignore[call-overload]
    assert error.value.status_code == status
    assert isinstance(error.value, openai.BadRequestError if status == 400
                      else openai.NotFoundError)
    assert says in error.value.message


def test_an_image_is_refused_naming_the_reason(api: openai.OpenAI) -> None:
    with pytest.raises(openai.BadRequestError) as error:
        api.chat.completions.create(model=MODEL, messages=[{"role": "user", "content": [
            {"type": "text", "text": "How many people are in this picture?"},
            {"type": "image_url", "image_url": {"url": "data:image/jpeg;base64,/9j/"}}]}])
    body = error.value.body
    assert isinstance(body, dict) and body["code"] == "image_input_not_supported"
    assert "no vision model" in body["message"]


def test_a_body_over_the_limit_is_413(api: openai.OpenAI) -> None:
    with pytest.raises(openai.APIStatusError) as error:
        api.chat.completions.create(model=MODEL, messages=[
            {"role": "user", "content": "x" * (2 * 1024 * 1024)}])
    assert error.value.status_code == 413
    assert "over this service's limit" in error.value.message


def test_a_call_over_the_limit_is_429_with_retry_after(llm_one_call: HttpService,
                                                       api: openai.OpenAI) -> None:
    # A streamed answer holds the service's only call slot until its last byte; its schema
    # makes it long (20 numbers at least), so it is still going while the others ask.
    many = {"type": "object", "required": ["numbers"], "properties": {
        "numbers": {"type": "array", "items": {"type": "integer"}, "minItems": 20}}}
    long_answer = {"model": MODEL, "stream": True, "max_tokens": 256, "temperature": 0,
                   "messages": [{"role": "user", "content": "List numbers in JSON."}],
                   "response_format": {"type": "json_schema",
                                       "json_schema": {"name": "numbers", "schema": many}}}
    with httpx.stream("POST", f"{llm_one_call.base_url}/v1/chat/completions", json=long_answer,
                      timeout=60) as stream:
        assert stream.status_code == 200
        next(stream.iter_lines())  # the answer has begun
        response = httpx.post(f"{llm_one_call.base_url}/v1/chat/completions", timeout=10, json={
            "messages": [{"role": "user", "content": QUESTION}]})
        assert response.status_code == 429
        assert int(response.headers["retry-after"]) >= 1
        assert int(response.headers["retry-after-ms"]) >= 100
        with pytest.raises(openai.RateLimitError):
            ask(api)
    # The slot is free again once the service has seen that client go, which it learns a
    # moment after the socket closes: the official client, retrying after the Retry-After it
    # is given, gets its answer.
    assert "4" in ask(client(llm_one_call, max_retries=3))


def test_a_client_still_sending_its_body_holds_no_call_slot(llm_one_call: HttpService,
                                                            api: openai.OpenAI) -> None:
    """A call slot is taken once a body is whole: with the service's only slot, callers over
    HTTP and gRPC are answered while a client sits on half a body (until the body's
    deadline, 30 s here)."""
    with socket.create_connection(("127.0.0.1", llm_one_call.port), timeout=10) as slow:
        slow.sendall(b"POST /v1/chat/completions HTTP/1.1\r\nHost: x\r\n"
                     b"Content-Type: application/json\r\nExpect: 100-continue\r\n"
                     b"Content-Length: 100\r\n\r\n")
        assert slow.recv(100).startswith(b"HTTP/1.1 100")  # the route is reading its body
        slow.sendall(b"{")
        assert "4" in ask(api)
        with grpc.insecure_channel(llm_one_call.grpc_address) as channel:
            language_pb2_grpc.LanguageModelStub(channel).Generate(
                language_pb2.GenerateRequest(prompt=QUESTION), timeout=30)


def test_503_until_the_model_is_loaded(tmp_path: Path) -> None:
    config = service_config("llm", {"server": {"http": {"listen": "127.0.0.1:0"}}})
    with local_service("llm", config, load=False) as host:
        assert host.http is not None
        service = HttpService(None, "", f"http://127.0.0.1:{host.http.port}")  # type: ignore[arg-type]
        assert health(service).status_code == 503
        with pytest.raises(openai.InternalServerError) as error:
            ask(client(service))
        assert error.value.status_code == 503 and "still loading" in error.value.message


def test_http_requests_are_counted_in_the_service_metrics() -> None:
    config = service_config("llm", {"server": {"http": {"listen": "127.0.0.1:0"},
                                               "metrics": {"listen": "127.0.0.1:0"}}})
    with local_service("llm", config, load=False) as host:
        assert host.http is not None and host.metrics_server is not None
        base = f"http://127.0.0.1:{host.http.port}"
        assert httpx.get(f"{base}/v1/models", timeout=10).status_code == 200
        assert httpx.post(f"{base}/v1/chat/completions", json={}, timeout=10).status_code == 400
        assert httpx.get(f"{base}/no/such/{'x' * 50}", timeout=10).status_code == 404
        metrics = scrape(host.metrics_server.url)
    count = "http_server_request_duration_seconds_count"
    assert metrics.value(count, http_route="/v1/models", http_request_method="GET",
                         http_response_status_code="200") == 1
    assert metrics.value(count, http_route="/v1/chat/completions",
                         http_response_status_code="400") == 1
    assert metrics.value(count, http_route="other", http_response_status_code="404") == 1
    assert metrics.value("http_server_active_requests", http_route="/v1/models") == 0


def test_sigterm_lets_a_streamed_answer_finish() -> None:
    with http_service("llm") as service:
        request = {"model": MODEL, "stream": True, "facts": FACTS,
                   "messages": [{"role": "user", "content": QUESTION}]}
        with httpx.stream("POST", f"{service.base_url}/v1/chat/completions", json=request,
                          timeout=30) as response:
            lines = response.iter_lines()
            first = next(line for line in lines if line)
            service.process.send_signal(signal.SIGTERM)  # drains: the answer completes
            rest = [line for line in lines if line]
        assert first.startswith("data: {") and rest[-1] == "data: [DONE]"
        text = "".join(json.loads(line[6:])["choices"][0]["delta"].get("content") or ""
                       for line in [first, *rest[:-1]])
        assert "4" in text
        assert service.process.wait(timeout=30) == 0


def test_a_client_leaving_mid_stream_stops_the_generation() -> None:
    config = service_config("llm", {"server": {"http": {"listen": "127.0.0.1:0"}}})
    with local_service("llm", config) as host:
        assert host.http is not None
        model = host.slot.peek()
        request = {"model": MODEL, "stream": True, "max_tokens": 256,
                   "response_format": {"type": "json_object"},  # rambles on to the limit
                   "messages": [{"role": "user", "content": "Describe the room in JSON."}]}
        url = f"http://127.0.0.1:{host.http.port}/v1/chat/completions"
        with httpx.stream("POST", url, json=request, timeout=30) as response:
            next(line for line in response.iter_lines() if '"content": "{' in line)
        # the connection is closed: the model stops within a token or so and is free again
        assert "4" in ask(client(HttpService(None, "", url.rpartition("/v1")[0])))  # type: ignore[arg-type]
        stats = model.stats
        assert stats.stopped_early == 1 and stats.completion_tokens < 256 + 10
