"""The gateway calling OpenAI-compatible servers (`protocol: openai`): llama.cpp's own server
(llama_cpp.server, a third-party engine) and ORICF's services with --http-listen, with the
same deadlines, retries, failover and recovery as gRPC endpoints, across protocols."""

from __future__ import annotations

import base64
import email.utils
import os
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import grpc
import httpx
import openai
import pytest

from oricf.errors import ConfigError
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, PipelineConfig, parse_pipeline
from oricf.gateway.endpoints.openai import retry_after_ms
from oricf.gateway.methods.chat import ChatTemplates, ImageContext, image_url, messages
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.products import ProductStore, Reading
from oricf.gateway.values import AudioClip, Frame, Record
from oricf.imaging import decode_image
from tests.support.data import video_frames
from tests.support.llama_server import LlamaServer, llama_server
from tests.support.openai_http import HttpService, http_service
from tests.support.services import RunningService
from tests.support.speech import speech

QUESTION = "How many people do you see?"


class Outputs(Emitter):
    def __init__(self) -> None:
        self.sent: list[tuple[str, Any]] = []

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sent.append((output.source, value))

    def values(self, field: str) -> list[Any]:
        return [value for source, value in self.sent if source == field]


def asking(llm: dict[str, Any], context: bool = True, **call: Any) -> PipelineConfig:
    """A typed question with the people count as context. The count's route is never fed:
    the test puts the count (4) into the data product itself."""
    return parse_pipeline({
        "endpoints": {"llm": {"deadline_ms": 60000, **llm}},
        "routes": {
            "count": {"input": {"topic": "/count", "type": "std_msgs/Int32"},
                      "call": {"service": "llm", "method": "Generate", "prompt": "{value}"},
                      "outputs": [{"product": "people_count", "from": "value"}]},
            "ask": {"input": {"text": "-"},
                    "call": {"service": "llm", "method": "Generate", "prompt": "{text}",
                             "max_tokens": 32, "temperature": 0, **call,
                             **({"context": {"products": ["people_count"]}} if context
                                else {})},
                    "outputs": [{"text": "-", "from": "answer"}]}}}, "test pipeline")


@pytest.fixture
def pipeline_for() -> Iterator[Callable[[PipelineConfig], tuple[Pipeline, Outputs]]]:
    started: list[Pipeline] = []

    def make(config: PipelineConfig) -> tuple[Pipeline, Outputs]:
        outputs = Outputs()
        # The facts' age stays 0.0 s, so every question is the same prompt (and answer).
        pipeline = Pipeline(config, outputs, ProductStore(clock=lambda: 0.0))
        pipeline.products.put("people_count", 4)
        pipeline.start()
        started.append(pipeline)
        return pipeline, outputs

    yield make
    for pipeline in started:
        pipeline.stop()


def ask(pipeline: Pipeline, question: str = QUESTION, timeout: float = 90) -> None:
    pipeline.submit("ask", lambda: {"text": question})
    assert pipeline.idle(timeout)


@pytest.fixture(scope="module")
def llama() -> Iterator[LlamaServer]:
    with llama_server() as server:
        yield server


def openai_endpoint(server: LlamaServer, **more: Any) -> dict[str, Any]:
    return {"protocol": "openai", "address": server.base_url, "model": server.alias, **more}


def test_a_typed_question_is_answered_through_llama_cpp_server(
        llama: LlamaServer, pipeline_for: Any) -> None:
    pipeline, outputs = pipeline_for(asking(openai_endpoint(llama)))
    ask(pipeline)
    [answer] = outputs.values("answer")
    assert "4" in answer, answer
    # What the gateway sent is the chat its templates make: the same answer, asked directly.
    reading = Reading("people_count", 4, 0.0, 5.0)
    direct = openai.OpenAI(base_url=llama.base_url, api_key="none").chat.completions.create(
        model=llama.alias, max_tokens=32, temperature=0,
        messages=messages(QUESTION, [reading], ChatTemplates(), None))  # type: ignore[arg-type]
    assert direct.choices[0].message.content.strip() == answer  # type: ignore[union-attr]


def test_a_streamed_answer_is_the_whole_answer(llama: LlamaServer, pipeline_for: Any) -> None:
    plain, plain_out = pipeline_for(asking(openai_endpoint(llama)))
    streamed, streamed_out = pipeline_for(asking(openai_endpoint(llama), stream=True))
    ask(plain)
    ask(streamed)
    assert streamed_out.values("answer") == plain_out.values("answer") != [""]


def test_grpc_streaming_joins_to_the_unary_answer(pipeline_for: Any, llm: RunningService) -> None:
    plain, plain_out = pipeline_for(asking({"address": llm.address}))
    streamed, streamed_out = pipeline_for(asking({"address": llm.address}, stream=True))
    ask(plain)
    ask(streamed)
    assert streamed_out.values("answer") == plain_out.values("answer")
    assert "4" in plain_out.values("answer")[0]


def test_failover_from_llama_cpp_server_to_oricf_grpc_and_back(pipeline_for: Any,
                                                               llm: RunningService) -> None:
    with llama_server() as server:
        config = asking(openai_endpoint(server, fallback={"address": llm.address},
                                        probe_interval_s=0.5))
        pipeline, outputs = pipeline_for(config)
        endpoint = pipeline.endpoints["llm"]
        ask(pipeline)
        assert endpoint.active is endpoint.primary and endpoint.failovers == 0
        # Killed mid-run: a question in flight (or the next one) is answered by the fallback.
        pipeline.submit("ask", lambda: {"text": QUESTION})
        time.sleep(0.1)
        server.kill()
        assert pipeline.idle(90)
        ask(pipeline)
        assert endpoint.failovers == 1 and endpoint.active is endpoint.fallback
        server.start()
        deadline = time.monotonic() + 20
        while endpoint.active is not endpoint.primary and time.monotonic() < deadline:
            time.sleep(0.1)
        assert endpoint.active is endpoint.primary and endpoint.recoveries == 1
        ask(pipeline)
    answers = outputs.values("answer")
    assert len(answers) == 4 and all("4" in a for a in answers), answers
    route = pipeline.routes["ask"].stats
    assert route.ok == 4 and route.call_errors == 0


def test_a_busy_server_is_retried_after_its_retry_after(pipeline_for: Any,
                                                        llm_one_call: HttpService) -> None:
    """ORICF's language service over HTTP with one call slot, held by a long streamed answer:
    the gateway's call gets 429 with Retry-After, waits, and is answered once the slot is
    free again."""
    config = asking({"protocol": "openai", "address": f"{llm_one_call.base_url}/v1",
                     "model": "gemma3-270m", "retry": {"attempts": 10}})
    pipeline, outputs = pipeline_for(config)
    begun = threading.Event()
    holding = threading.Thread(target=_hold_the_slot, args=(llm_one_call, 2.0, begun))
    holding.start()
    assert begun.wait(60), "the long answer did not begin"
    ask(pipeline)
    holding.join()
    assert pipeline.endpoints["llm"].retries >= 1
    assert pipeline.routes["ask"].stats.ok == 1 and outputs.values("answer") != [""]


# An answer of 20 numbers at least: long enough to hold the slot while the gateway asks.
MANY_NUMBERS = {"type": "object", "required": ["numbers"], "properties": {
    "numbers": {"type": "array", "items": {"type": "integer"}, "minItems": 20}}}


def _hold_the_slot(llm: HttpService, seconds: float, begun: threading.Event) -> None:
    """A streamed answer holds the service's only slot (a slot is taken once a request's
    body is whole) until this client leaves, `seconds` after the answer began."""
    body = {"model": "gemma3-270m", "stream": True, "max_tokens": 256, "temperature": 0,
            "messages": [{"role": "user", "content": "List numbers in JSON."}],
            "response_format": {"type": "json_schema",
                                "json_schema": {"name": "numbers", "schema": MANY_NUMBERS}}}
    with httpx.stream("POST", f"{llm.base_url}/v1/chat/completions", json=body,
                      timeout=60) as stream:
        lines = stream.iter_lines()
        next(lines)
        begun.set()
        deadline = time.monotonic() + seconds
        for _ in lines:
            if time.monotonic() > deadline:
                break


def test_an_image_part_reaches_the_server_which_refuses_it_by_name(
        pipeline_for: Any, llm_one_call: HttpService) -> None:
    """ORICF's own language service has no vision: the frame the gateway attached arrives as
    an image_url part and is refused with a 400 that names it."""
    config = asking({"protocol": "openai", "address": f"{llm_one_call.base_url}/v1",
                     "model": "gemma3-270m"}, context=False, image={"product": "people_count"})
    pipeline, outputs = pipeline_for(config)
    pipeline.products.put("people_count", Frame.from_pixels(video_frames([0])[0]))
    ask(pipeline)
    stats = pipeline.routes["ask"].stats
    assert stats.call_errors == 1 and "INVALID_ARGUMENT" in stats.errors
    assert outputs.values("answer") == []


def test_transcribe_through_an_openai_transcriptions_server(
        asr_small_uploads: HttpService) -> None:
    config = parse_pipeline({
        "endpoints": {"asr": {"protocol": "openai",
                              "address": f"{asr_small_uploads.base_url}/v1",
                              "model": "whisper-tiny-en", "deadline_ms": 30000}},
        "routes": {"speech": {
            "input": {"topic": "/audio", "type": "std_msgs/Int16MultiArray"},
            "call": {"service": "asr", "method": "Transcribe", "language": "en"},
            "outputs": [{"jsonl": "-", "from": "transcript"},
                        {"jsonl": "-", "from": "duration_s"}]}}}, "asr pipeline")
    outputs = Outputs()
    pipeline = Pipeline(config, outputs)
    pipeline.start()
    try:
        samples = speech(QUESTION)
        clip = AudioClip(samples.astype("<i2").tobytes(), 16000, 1)
        pipeline.submit("speech", lambda: {"audio": clip})
        assert pipeline.idle(60)
    finally:
        pipeline.stop()
    [transcript] = outputs.values("transcript")
    assert "people" in transcript.lower(), transcript
    assert outputs.values("duration_s") == [pytest.approx(clip.duration_s)]


def test_a_hung_server_costs_one_deadline_then_the_fallback_answers(
        pipeline_for: Any, llm: RunningService) -> None:
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    held: list[socket.socket] = []
    threading.Thread(target=lambda: held.extend([listener.accept()[0] for _ in range(8)]),
                     daemon=True).start()
    try:
        config = asking({"protocol": "openai", "model": "m", "deadline_ms": 1500,
                         "address": f"http://127.0.0.1:{listener.getsockname()[1]}/v1",
                         "fallback": {"address": llm.address}})
        pipeline, outputs = pipeline_for(config)
        started = time.monotonic()
        ask(pipeline)
        assert time.monotonic() - started >= 1.5
    finally:
        listener.close()
    endpoint = pipeline.endpoints["llm"]
    assert endpoint.failovers == 1 and "4" in outputs.values("answer")[0]


def test_an_unreachable_server_without_fallback_is_a_counted_call_error(
        pipeline_for: Any) -> None:
    from tests.support.processes import free_port

    config = asking({"protocol": "openai", "model": "m",
                     "address": f"http://127.0.0.1:{free_port()}/v1"})
    pipeline, outputs = pipeline_for(config)
    ask(pipeline)
    stats = pipeline.routes["ask"].stats
    assert stats.call_errors == 1 and stats.errors == {grpc.StatusCode.UNAVAILABLE.name: 1}
    assert outputs.values("answer") == []


def test_the_token_goes_in_the_header_and_never_into_the_log(
        tmp_path: Any, pipeline_for: Any, caplog: pytest.LogCaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    tokens = tmp_path / "tokens"
    tokens.write_text("s3cret-token\n")
    overlay = tmp_path / "auth.yaml"
    overlay.write_text(f"server: {{auth: {{file: {tokens}}}}}\n")
    monkeypatch.setenv("LLM_TOKEN", "s3cret-token")
    with http_service("llm", "--overlay", str(overlay)) as http_llm:
        base = {"protocol": "openai", "address": f"{http_llm.base_url}/v1", "model": "gemma3-270m"}
        good, good_out = pipeline_for(asking({**base, "token": {"env": "LLM_TOKEN"}}))
        bad, _ = pipeline_for(asking(base))
        ask(good)
        ask(bad)
    assert good.routes["ask"].stats.ok == 1 and good_out.values("answer") != [""]
    assert bad.routes["ask"].stats.errors == {"UNAUTHENTICATED": 1}
    assert "s3cret-token" not in caplog.text


OPENAI = {"protocol": "openai", "address": "http://127.0.0.1:9/v1", "model": "m"}
MISTAKES = [
    ({**OPENAI, "address": "127.0.0.1:9"}, "endpoints.llm.address: '127.0.0.1:9' is not an http"),
    ({**OPENAI, "address": "http://user:pw@host:9/v1"}, "no user or password in the URL"),
    ({**OPENAI, "address": "ftp://host/v1"}, "is not an http:// or https:// URL"),
    ({"address": "http://host:9/v1"}, "say `protocol: openai`"),
    ({"protocol": "openai", "address": "http://host:9/v1"}, "model: required with protocol"),
    ({"address": "127.0.0.1:9", "model": "m"}, "model: only with protocol openai"),
    ({**OPENAI, "tls": {"ca": __file__}}, "the address is http://; use https://"),
    ({**OPENAI, "fallback": "127.0.0.1:50053"}, "endpoints.llm.fallback: '127.0.0.1:50053' is "
                                                "not an http"),
]


@pytest.mark.parametrize(("endpoint", "message"), MISTAKES)
def test_endpoint_mistakes_name_the_key(endpoint: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError) as error:
        asking(endpoint)
    assert message in str(error.value)


def test_a_ca_that_is_a_fifo_is_refused_at_once_naming_the_key(tmp_path: Path,
                                                                 pipeline_for: Any) -> None:
    """The ssl module would open the CA by name and wait for a writer for ever."""
    fifo = tmp_path / "ca.fifo"
    os.mkfifo(fifo, 0o600)
    config = asking({**OPENAI, "address": "https://127.0.0.1:9/v1", "tls": {"ca": str(fifo)}})
    with pytest.raises(ConfigError) as error:
        pipeline_for(config)
    assert f"tls.ca: {fifo}: a FIFO (named pipe)" in str(error.value)


def test_a_method_without_openai_calls_is_refused_on_such_an_endpoint() -> None:
    with pytest.raises(ConfigError) as error:
        parse_pipeline({
            "endpoints": {"detector": {"address": "127.0.0.1:50051", "fallback": OPENAI}},
            "routes": {"people": {"input": {"url": "x.mp4"},
                                  "call": {"service": "detector", "method": "Detect"},
                                  "outputs": [{"jsonl": "-", "from": "detections"}]}}}, "p")
    assert ("routes.people.call.service: the endpoint's fallback speaks openai, which Detect "
            "does not") in str(error.value)


def test_the_image_part_is_a_jpeg_scaled_to_fit_and_never_a_stale_frame() -> None:
    store = ProductStore(clock=lambda: 0.0)
    store.declare("camera", 1.0)
    assert image_url(store, ImageContext(product="camera")) is None  # nothing yet
    store.put("camera", Frame.from_pixels(video_frames([0])[0]))  # 768x576
    url = image_url(store, ImageContext(product="camera", max_side=320))
    assert url is not None and url.startswith("data:image/jpeg;base64,")
    jpeg = base64.b64decode(url.partition(",")[2])
    assert decode_image(jpeg, "jpeg").shape == (240, 320, 3)
    later = ProductStore(clock=iter([0.0, 5.0]).__next__)
    later.declare("camera", 1.0)
    later.put("camera", Frame.from_pixels(video_frames([0])[0]))
    assert image_url(later, ImageContext(product="camera")) is None  # 5 s old: stale


def test_facts_become_the_system_message_with_the_stale_rules() -> None:
    readings = [Reading("people_count", 4, 0.5, 5.0), Reading("door", None, 9.0, 5.0)]
    chat = messages(QUESTION, readings, ChatTemplates(), None)
    assert chat == [
        {"role": "system", "content": "What the robot's sensors say now, each with its age:\n"
                                      "- people_count: 4 (0.5 s ago)\n"
                                      "- door: unknown (9.0 s ago, stale)"},
        {"role": "user", "content": QUESTION}]
    assert messages(QUESTION, [], ChatTemplates(), None) == [
        {"role": "user", "content": QUESTION}]


@pytest.mark.parametrize(("header", "expected_ms"), [
    (None, 0.0), ("2", 2000.0), ("0.5", 500.0), ("soon", 0.0), ("-3", 0.0)])
def test_retry_after_reads_seconds(header: str | None, expected_ms: float) -> None:
    assert retry_after_ms(header) == expected_ms


def test_retry_after_reads_an_http_date() -> None:
    when = email.utils.formatdate(time.time() + 3, usegmt=True)
    assert 1000 < retry_after_ms(when) <= 3000
