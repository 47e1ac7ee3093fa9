"""Hostile input on the services' HTTP side (the OpenAI-compatible API), against real
`oricf serve llm|asr --http-listen` processes: fuzzed JSON bodies, bytes that are not JSON,
10 MB bodies, uploads that are not audio, lying Content-Lengths, slow clients (slowloris),
half-sent bodies, lone UTF-16 surrogates, 200 connections at once and more silent
connections than the connection limit. Every answer is a client error in OpenAI's shape or
a limit, never a 500; memory stays bounded; the service answers normally afterwards."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from typing import Any

import grpc
import httpx
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.audio import encode_wav
from oricf.http_connections import MIN_IDLE_S
from oricf.v1 import language_pb2, language_pb2_grpc
from tests.support.fuzzing import examples
from tests.support.openai_http import HttpService, client, health, http_service, overlay, rss_mb
from tests.support.sockets import inet_sockets, peer_closed

REQUEST_TIMEOUT_S = 2.0
# The speech service's body deadline is long, so that an answer that waited for it could
# not pass for one given at once.
ASR_REQUEST_TIMEOUT_S = 30.0
MAX_UPLOAD_BYTES = 25 * 1024 * 1024
MAX_CONNECTIONS = 64
MAX_CONCURRENT_RPCS = 4
CLIENT_ERRORS = {400, 404, 408, 413, 429}
MAX_GROWTH_MB = 300
QUESTION = {"messages": [{"role": "user", "content": "How many people do you see?"}]}

SERVER: dict[str, Any] = {
    "max_concurrent_rpcs": MAX_CONCURRENT_RPCS,
    "http": {"request_timeout_s": REQUEST_TIMEOUT_S, "max_connections": MAX_CONNECTIONS,
             "keep_alive_s": 2}}
ASR_SERVER = {**SERVER, "http": {**SERVER["http"], "request_timeout_s": ASR_REQUEST_TIMEOUT_S}}
# Idle connections on `patient_llm`: more than its connection limit. Its header deadline is
# far beyond any wait in their test, so only room made for a new connection explains an
# answer there.
SILENT = MAX_CONNECTIONS + 6
PATIENT_REQUEST_TIMEOUT_S = 60.0
WAIT_S = 10.0
LLM_MODEL = "gemma3-270m"
SHORT_ANSWERS = {"max_tokens": 2, "max_tokens_limit": 4}


@pytest.fixture(scope="module")
def short_llm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    folder = tmp_path_factory.mktemp("llm")
    short = overlay(folder, {"server": SERVER, "generation": SHORT_ANSWERS})
    with http_service("llm", "--overlay", short) as service:
        yield service


@pytest.fixture(scope="module")
def patient_llm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    folder = tmp_path_factory.mktemp("patient_llm")
    patient = {**SERVER, "http": {**SERVER["http"],
                                  "request_timeout_s": PATIENT_REQUEST_TIMEOUT_S}}
    with http_service("llm", "--overlay", overlay(folder, {"server": patient,
                                                           "generation": SHORT_ANSWERS})
                      ) as service:
        yield service


@pytest.fixture(scope="module")
def limited_asr(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    folder = tmp_path_factory.mktemp("asr")
    with http_service("asr", "--overlay", overlay(folder, {"server": ASR_SERVER})) as service:
        yield service


def assert_openai_error(response: httpx.Response) -> None:
    assert response.status_code in CLIENT_ERRORS, (response.status_code, response.text)
    error = response.json()["error"]
    assert set(error) == {"message", "type", "param", "code"} and error["message"]
    assert "Traceback" not in response.text


def still_serving(service: HttpService) -> None:
    assert health(service).status_code == 200
    response = httpx.post(f"{service.base_url}/v1/chat/completions", json=QUESTION, timeout=30)
    if "llm" in service.process.args:  # type: ignore[operator]
        assert response.status_code == 200, response.text


HOSTILE = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70),
                    st.floats(allow_nan=False), st.text(max_size=60),
                    st.sampled_from(["user", "system", "assistant", "tool", "image_url",
                                     "json_schema", "gemma3-270m", "x" * 5000, "\ud800",
                                     "a\udfffb", "\ud83d"]))
VALUES = st.recursive(HOSTILE, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=12), inner, max_size=4)),
    max_leaves=12)
MESSAGE = st.fixed_dictionaries({"role": st.sampled_from(["user", "system", "assistant", "x"])},
                                optional={"content": VALUES})
FIELDS = {"model": VALUES, "messages": st.one_of(st.lists(MESSAGE, max_size=3), VALUES),
          "max_tokens": VALUES, "temperature": VALUES, "top_p": VALUES, "stop": VALUES,
          "seed": VALUES, "stream": VALUES, "response_format": VALUES, "facts": VALUES,
          "n": VALUES, "stream_options": VALUES}


@settings(max_examples=examples(150), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(body=st.fixed_dictionaries({}, optional=FIELDS))
def test_fuzzed_chat_bodies_get_clear_answers(short_llm: HttpService, body: dict[str, Any]) -> None:
    response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", timeout=30,
                          content=json.dumps(body),
                          headers={"Content-Type": "application/json"})
    if response.status_code != 200:
        assert_openai_error(response)


@settings(max_examples=examples(60), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=st.binary(max_size=300))
def test_bytes_that_are_not_json_are_400(short_llm: HttpService, body: bytes) -> None:
    response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", content=body, timeout=30)
    if response.status_code != 200:  # an accident of valid JSON is answered
        assert_openai_error(response)


# A FLAC STREAMINFO declaring 29.5 s at 384 kHz in 8 channels (173 MB of samples), and a WAV
# header declaring 384 kHz in 32 channels with its data running to the end of the file.
BIG_FLAC = (b"fLaC\x80\x00\x00\x22" + b"\x10\x00\x10\x00" + bytes(6)
            + ((384_000 << 44) | (7 << 41) | (15 << 36) | 11_328_000).to_bytes(8, "big")
            + bytes(16))
WIDE_WAV = b"".join([b"RIFF\xff\xff\xff\xffWAVEfmt \x10\x00\x00\x00\x01\x00\x20\x00",
                     (384_000).to_bytes(4, "little"), bytes(4), b"\x40\x00\x10\x00",
                     b"data\xff\xff\xff\x7f"])
AUDIO_HEADERS = [b"RIFF\x24\x00\x00\x00WAVEfmt ", b"RIFF\xff\xff\xff\xffWAVE", b"fLaC",
                 b"fLaC\x00\x00\x00\x22", b"OggS\x00\x02", b"ID3\x04\x00", b"\xff\xfb\x90",
                 BIG_FLAC, WIDE_WAV, b""]


@settings(max_examples=examples(120), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.builds(lambda head, rest: head + rest, st.sampled_from(AUDIO_HEADERS),
                      st.binary(max_size=3000)),
       response_format=st.sampled_from(["json", "text", "verbose_json"]))
def test_fuzzed_uploads_get_clear_answers(limited_asr: HttpService, data: bytes,
                                          response_format: str) -> None:
    """Bytes behind the magic of each format the service reads, FFmpeg's formats too."""
    response = httpx.post(f"{limited_asr.base_url}/v1/audio/transcriptions", timeout=30,
                          files={"file": ("fuzz", data)},
                          data={"response_format": response_format})
    if response.status_code != 200:
        assert_openai_error(response)
    assert limited_asr.process.poll() is None


def test_ten_megabyte_bodies_are_refused_with_bounded_memory(short_llm: HttpService,
                                                             limited_asr: HttpService) -> None:
    before = rss_mb(short_llm.process.pid), rss_mb(limited_asr.process.pid)
    big = b"{" + b" " * (10 * 1024 * 1024) + b"}"
    for _ in range(5):
        response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", content=big, timeout=30)
        assert response.status_code == 413
        assert_openai_error(response)
    noise = {"file": ("noise.wav", bytes(range(256)) * 40_000)}  # 10 MB that is not audio
    response = httpx.post(f"{limited_asr.base_url}/v1/audio/transcriptions", files=noise,
                          timeout=30)
    assert response.status_code == 400 and "not audio" in response.json()["error"]["message"]
    assert rss_mb(short_llm.process.pid) - before[0] < MAX_GROWTH_MB
    assert rss_mb(limited_asr.process.pid) - before[1] < MAX_GROWTH_MB
    still_serving(short_llm)


@pytest.mark.parametrize("form", [
    {"data": {"model": "whisper-tiny-en"}},                              # no file
    {"data": {f"field{i}": "x" for i in range(40)}, "files": {"file": ("a.wav", b"RIFF")}},
    {"data": {"language": "x" * 100_000}, "files": {"file": ("a.wav", b"RIFF")}},
    {"files": {"file": ("a.mp3", b"\xff\xfb" + bytes(5000))}},            # MP3 sync, no frames
    {"files": {"file": ("a.wav", b"RIFF\xff\xff\xff\xffWAVEfmt " + bytes(64))}},
])
def test_hostile_uploads_are_client_errors(limited_asr: HttpService, form: dict[str, Any]) -> None:
    response = httpx.post(f"{limited_asr.base_url}/v1/audio/transcriptions", timeout=30, **form)
    assert_openai_error(response)


def raw(service: HttpService, data: bytes, wait_s: float = 0.0) -> bytes:
    """Sends bytes on a fresh connection and returns what came back before it closed."""
    with socket.create_connection(("127.0.0.1", service.port), timeout=15) as sock:
        sock.sendall(data)
        time.sleep(wait_s)
        chunks = []
        try:
            while chunk := sock.recv(65536):
                chunks.append(chunk)
        except (ConnectionResetError, TimeoutError):
            pass
        return b"".join(chunks)


def test_lying_content_lengths(short_llm: HttpService) -> None:
    head = b"POST /v1/chat/completions HTTP/1.1\r\nHost: x\r\nConnection: close\r\n"
    # More promised than sent: the body's deadline passes, 408.
    answer = raw(short_llm, head + b"Content-Length: 1000\r\n\r\n{\"messages\": ")
    assert answer.startswith(b"HTTP/1.1 408") and b'"request_timeout"' in answer
    # Less promised than sent: the body is what was promised (not JSON), the rest is not HTTP.
    answer = raw(short_llm, head + b"Content-Length: 5\r\n\r\n" + json.dumps(QUESTION).encode())
    assert answer.startswith(b"HTTP/1.1 400")
    # A Content-Length that is not a number is refused before any route runs.
    answer = raw(short_llm, head + b"Content-Length: lots\r\n\r\n{}")
    assert answer.startswith(b"HTTP/1.1 400")
    # Far more promised than the limit, and nothing sent: 413, not a wait for the body.
    answer = raw(short_llm, head + b"Content-Length: 99999999999999\r\n\r\n")
    assert answer.startswith(b"HTTP/1.1 413") and b'"request_too_large"' in answer
    still_serving(short_llm)


CHAT_HEAD = (b"POST /v1/chat/completions HTTP/1.1\r\nHost: x\r\n"
             b"Content-Type: application/json\r\n")
UPLOAD_HEAD = (b"POST /v1/audio/transcriptions HTTP/1.1\r\nHost: x\r\n"
               b"Content-Type: multipart/form-data; boundary=hostile\r\n")
FILE_PART = (b'--hostile\r\nContent-Disposition: form-data; name="file"; filename="a.wav"\r\n'
             b"Content-Type: audio/wav\r\n\r\n")


def until_closed(sock: socket.socket, timeout_s: float) -> bytes:
    """What comes back on sock until the server ends its side; TimeoutError if it has not
    within timeout_s (a deadline, not a measure: what is asked for comes at once)."""
    sock.settimeout(timeout_s)
    chunks = []
    while chunk := sock.recv(65536):
        chunks.append(chunk)
    return b"".join(chunks)


def continued(sock: socket.socket) -> None:
    """Waits for `100 Continue`: uvicorn sends it when the route first reads the body, so
    the request has passed every guard by then."""
    sock.settimeout(15)
    seen = b""
    while b"\r\n\r\n" not in seen:
        chunk = sock.recv(1)
        assert chunk, "closed before 100 Continue"
        seen += chunk
    assert seen.startswith(b"HTTP/1.1 100"), seen


def test_half_sent_bodies_hold_no_call_slot(short_llm: HttpService) -> None:
    """Twice as many clients as call slots send a POST's headers and 10 bytes of its body,
    then stall: a caller over HTTP and one over gRPC are answered meanwhile (a call slot is
    taken once a body is whole), and each stalled client is answered 408 and disconnected
    at the body's deadline."""
    stalled = [socket.create_connection(("127.0.0.1", short_llm.port), timeout=15)
               for _ in range(2 * MAX_CONCURRENT_RPCS)]
    try:
        for sock in stalled:
            sock.sendall(CHAT_HEAD + b"Expect: 100-continue\r\nContent-Length: 1000\r\n\r\n")
        for sock in stalled:
            continued(sock)
            sock.sendall(b'{"messages')
        response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", json=QUESTION,
                              timeout=30)
        assert response.status_code == 200, response.text
        with grpc.insecure_channel(short_llm.grpc_address) as channel:
            answer = language_pb2_grpc.LanguageModelStub(channel).Generate(
                language_pb2.GenerateRequest(prompt=QUESTION["messages"][0]["content"]),
                timeout=30)
        assert answer.finish_reason in ("stop", "length")
        for sock in stalled:
            refusal = until_closed(sock, REQUEST_TIMEOUT_S + 10)
            assert refusal.startswith(b"HTTP/1.1 408") and b'"request_timeout"' in refusal
    finally:
        for sock in stalled:
            sock.close()
    still_serving(short_llm)


def test_an_upload_declared_over_the_limit_is_413_before_its_body(limited_asr: HttpService) -> None:
    """Only the headers, saying a terabyte is coming: 413 at once, long before the body's
    deadline, and the connection is closed."""
    with socket.create_connection(("127.0.0.1", limited_asr.port), timeout=15) as sock:
        sock.sendall(UPLOAD_HEAD + b"Content-Length: 1000000000000\r\n\r\n")
        refusal = until_closed(sock, ASR_REQUEST_TIMEOUT_S / 2)
    assert refusal.startswith(b"HTTP/1.1 413") and b'"request_too_large"' in refusal
    assert b"connection: close" in refusal.lower()


def test_a_chunked_upload_past_the_limit_is_413_at_once(limited_asr: HttpService) -> None:
    """A chunked body has no length to be refused by: it is cut off where it crosses the
    upload limit and answered 413 without waiting for the rest (which never comes here)."""
    chunk = bytes(1024 * 1024)
    with socket.create_connection(("127.0.0.1", limited_asr.port), timeout=15) as sock:
        sock.sendall(UPLOAD_HEAD + b"Transfer-Encoding: chunked\r\n\r\n"
                     + b"%x\r\n%s\r\n" % (len(FILE_PART), FILE_PART))
        try:
            for _ in range(MAX_UPLOAD_BYTES // len(chunk) + 2):
                sock.sendall(b"%x\r\n%s\r\n" % (len(chunk), chunk))
        except OSError:  # the server stopped reading: the answer is waiting
            pass
        refusal = until_closed(sock, ASR_REQUEST_TIMEOUT_S / 2)
    assert refusal.startswith(b"HTTP/1.1 413") and b'"request_too_large"' in refusal
    assert health(limited_asr).status_code == 200


SURROGATE_BODIES = [
    ({"messages": [{"role": "user", "content": "How many? \ud800"}]}, "messages[0].content"),
    ({"messages": [{"role": "system", "content": "Be brief.\udfff"}, *QUESTION["messages"]]},
     "messages[0].content"),
    ({"messages": [{"role": "user", "content": [{"type": "text", "text": "\ud83d"}]}]},
     "messages[0].content[0].text"),
    ({**QUESTION, "stop": ["\ud800"]}, "stop[0]"),
    ({**QUESTION, "stop": "\ud800"}, "stop"),
    ({**QUESTION, "model": "gemma\ud800"}, "model"),
    ({**QUESTION, "stream": True, "messages": [{"role": "user", "content": "\ud800"}]},
     "messages[0].content"),
    ({**QUESTION, "stream": True, "stop": "\udc00"}, "stop"),
    ({**QUESTION, "facts": [{"name": "people\ud800", "integer": 1}]}, "facts[0].name"),
    ({**QUESTION, "x\ud800": 1}, "(a key)"),
]


@pytest.mark.parametrize(("body", "field"), SURROGATE_BODIES)
def test_lone_surrogates_are_400_naming_the_field(short_llm: HttpService, body: dict[str, Any],
                                                  field: str) -> None:
    """`"\\ud800"` (a surrogate without its pair) anywhere in a body is not text."""
    response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", content=json.dumps(body),
                          headers={"Content-Type": "application/json"}, timeout=30)
    assert response.status_code == 400, response.text
    assert_openai_error(response)
    error = response.json()["error"]
    assert error["param"] == field and "surrogate" in error["message"]


def test_lone_surrogates_as_bytes_are_400(short_llm: HttpService) -> None:
    """The same surrogate as the three bytes that would encode it (Python's JSON decoder
    lets them through)."""
    body = b'{"messages": [{"role": "user", "content": "\xed\xa0\x80"}]}'
    response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", content=body, timeout=30)
    assert response.status_code == 400, response.text
    assert response.json()["error"]["param"] == "messages[0].content"
    still_serving(short_llm)


SILENCE = encode_wav(np.zeros(8000, dtype=np.int16), 16000)  # half a second, real audio


def form(fields: dict[str, bytes], charset: str | None = None) -> tuple[bytes, dict[str, str]]:
    """A multipart body with a small file and these text fields, as raw bytes (a client
    library would refuse to encode some of them)."""
    parts = [b'--hostile\r\nContent-Disposition: form-data; name="%s"\r\n\r\n%s\r\n'
             % (name.encode(), value) for name, value in fields.items()]
    body = b"".join(parts) + FILE_PART + SILENCE + b"\r\n--hostile--\r\n"
    kind = "multipart/form-data; boundary=hostile"
    return body, {"Content-Type": kind + (f"; charset={charset}" if charset else "")}


@pytest.mark.parametrize("name", ["model", "prompt", "language", "response_format",
                                  "temperature"])
@pytest.mark.parametrize(("value", "charset"), [
    (b"\\ud800", "unicode_escape"),       # the form's charset makes a lone surrogate of it
    (b"x\\udfffy", "raw_unicode_escape"),
    (b"\xed\xa0\x80", None),              # the bytes of one, in a UTF-8 form
    (b"\xed\xa0\x80", "utf-8"),
])
def test_lone_surrogates_in_form_fields_are_client_errors(limited_asr: HttpService, name: str,
                                                          value: bytes,
                                                          charset: str | None) -> None:
    body, headers = form({name: value}, charset)
    response = httpx.post(f"{limited_asr.base_url}/v1/audio/transcriptions", content=body,
                          headers=headers, timeout=30)
    assert_openai_error(response)
    if charset and "escape" in charset:
        assert response.json()["error"]["param"] == "content-type"
    assert limited_asr.process.poll() is None


def test_slow_clients_are_cut_off_and_others_served(short_llm: HttpService) -> None:
    slow = [socket.create_connection(("127.0.0.1", short_llm.port), timeout=15) for _ in range(10)]
    started = time.monotonic()
    try:
        for sock in slow:
            sock.sendall(b"GET /v1/models HTTP/1.1\r\nHost: x\r\n")  # headers never end
        still_serving(short_llm)  # meanwhile
        closed = 0
        while closed < len(slow) and time.monotonic() - started < REQUEST_TIMEOUT_S + 10:
            for sock in slow:
                try:
                    sock.sendall(b"X-Slow: 1\r\n")  # a header a second, for ever
                except OSError:
                    continue
            time.sleep(1.0)
            closed = sum(peer_closed(sock) for sock in slow)
        assert closed == len(slow)
        assert time.monotonic() - started < REQUEST_TIMEOUT_S + 5
    finally:
        for sock in slow:
            sock.close()
    still_serving(short_llm)


TCP_ESTABLISHED = "01"  # /proc's hex state of a connected TCP socket


def accepted(service: HttpService) -> int:
    """Connections the service's process has accepted on its HTTP port."""
    return sum(sock.port == service.port and sock.state == TCP_ESTABLISHED
               for sock in inet_sockets(service.process.pid))


HALF_HEADERS = b"GET /v1/models HTTP/1.1\r\nHost: x\r\n"  # the headers never end


@pytest.mark.parametrize("first_bytes", [b"", HALF_HEADERS], ids=["silent", "half-headers"])
def test_idle_connections_never_lock_a_client_out(patient_llm: HttpService,
                                                  first_bytes: bytes) -> None:
    """More connections than `max_connections` that send nothing, or headers that never
    end: once they have waited MIN_IDLE_S, the OpenAI client's first request on a fresh
    connection is answered 200, three times over (as many of the idle connections as it
    takes are closed for it), long before the header deadline could close them, and most of
    them stay open."""
    with ExitStack() as stack:
        idle = [stack.enter_context(socket.create_connection(("127.0.0.1", patient_llm.port),
                                                             timeout=15))
                for _ in range(SILENT)]
        for sock in idle:
            sock.sendall(first_bytes)
        deadline = time.monotonic() + WAIT_S
        while accepted(patient_llm) < SILENT and time.monotonic() < deadline:
            time.sleep(0.05)
        assert accepted(patient_llm) >= SILENT
        time.sleep(2 * MIN_IDLE_S)  # the age a connection needs before it may go for room
        for _ in range(3):
            with client(patient_llm) as fresh:
                answer = fresh.chat.completions.create(model=LLM_MODEL, messages=[
                    {"role": "user", "content": QUESTION["messages"][0]["content"]}])
            assert answer.choices[0].finish_reason in ("stop", "length")
        assert sum(peer_closed(sock) for sock in idle) < len(idle) // 2
    still_serving(patient_llm)


def test_200_connections_at_once(short_llm: HttpService) -> None:
    before = rss_mb(short_llm.process.pid)
    url = f"{short_llm.base_url}/v1/chat/completions"

    def one(_: int) -> int:
        try:
            return httpx.post(url, json=QUESTION, timeout=60).status_code
        except httpx.TransportError:
            return 0  # refused at the connection limit

    with ThreadPoolExecutor(max_workers=200) as pool:
        statuses = list(pool.map(one, range(200)))
    assert set(statuses) <= {0, 200, 429, 503}, statuses
    assert statuses.count(200) >= 1 and statuses.count(429) + statuses.count(503) >= 1
    assert rss_mb(short_llm.process.pid) - before < MAX_GROWTH_MB
    still_serving(short_llm)


PATTERN_ATOMS = st.sampled_from(["a", "[0-9]", ".", "\\d", "(a|b)", "\\x00", "[^a]", "[b-a]"])
PATTERNS = st.recursive(PATTERN_ATOMS, lambda inner: st.one_of(
    st.builds(lambda item, low, high: f"({item}){{{low},{high}}}", inner,
              st.integers(0, 3000), st.integers(0, 3000)),
    st.builds(lambda item: f"({item})?", inner),
    st.builds(lambda first, second: first + second, inner, inner),
    st.builds(lambda first, second: f"{first}|{second}", inner, inner)), max_leaves=6)
SCHEMAS = st.one_of(
    st.builds(lambda pattern: {"type": "string", "pattern": f"^{pattern}$"}, PATTERNS),
    st.builds(lambda patterns: {"anyOf": [{"type": "string", "pattern": f"^{pattern}$"}
                                          for pattern in patterns]},
              st.lists(PATTERNS, min_size=1, max_size=40)),
    st.builds(lambda length, items: {"type": "array", "maxItems": items, "items": {
        "type": "string", "maxLength": length}}, st.integers(0, 2000), st.integers(0, 2000)))


@settings(max_examples=examples(80), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(schema=SCHEMAS, stream=st.booleans())
def test_fuzzed_json_schemas_never_take_the_language_service_down(
        short_llm: HttpService, schema: dict[str, Any], stream: bool) -> None:
    """Counted repetitions nested in each other, optional runs, look-alike alternatives,
    characters no token gives: answered (the grammar is within the limits) or refused with
    a 400 naming the limit, and the process lives on."""
    body = {**QUESTION, "stream": stream, "response_format": {
        "type": "json_schema", "json_schema": {"name": "x", "schema": schema}}}
    response = httpx.post(f"{short_llm.base_url}/v1/chat/completions", json=body, timeout=120)
    if response.status_code != 200:
        assert response.status_code == 400
        assert_openai_error(response)
    assert short_llm.process.poll() is None
