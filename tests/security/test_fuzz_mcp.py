"""Hostile agents and callers of `oricf mcp` and the gateway's control API, over real sockets
against a real gateway (the real detector; the policy's topics heard by a real rclpy node):

- raw HTTP to the MCP endpoint: random bytes, random JSON-RPC, lying and oversized bodies;
- raw lines to `oricf mcp` over stdio: random bytes, random JSON-RPC, batches, surrogates,
  ids that are neither integers nor strings, a line over the bound;
- tool calls through the `mcp` SDK's client with arguments drawn from hostile JSON values;
- requests to every path of the control API on its Unix socket;
- seventy idle connections (silent, or headers never finished) beside a client that asks;
- numbers no message field holds (NaN, infinities, 1e309, 400 digits) in raw JSON-RPC.

Whatever arrives: an HTTP status that names a client mistake (never 5xx), a tool result or
an MCP error (never a dead server), a JSON-RPC error for each stdio line that is no message,
no command outside the policy's bounds on the robot's topics, bounded memory, and a
well-formed call still served afterwards."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcp_types import JSONRPCNotification, jsonrpc_message_adapter
from pydantic import ValidationError

from tests.gateway.agents.raw import RawStdio, approval_pipeline
from tests.gateway.agents.scene import PEOPLE, RosListener, pipeline_yaml, ros_listener
from tests.gateway.agents.session import TOOLS, http_session, server_env
from tests.gateway.ros.gateway_node import private_domain
from tests.support.fuzzing import examples
from tests.support.processes import free_port
from tests.support.services import RunningService
from tests.support.sockets import peer_closed

EXAMPLES = examples(120)
TOKEN = "fuzz-token-71"
MAX_GROWTH_MB = 400
MAX_STDIO_LINE_BYTES = 16 * 1024 * 1024
CONTROL_PATHS = ["/v1/products", "/v1/products/people_count", "/v1/look", "/v1/status",
                 "/v1/policy", "/v1/detect", "/v1/infer", "/v1/ask", "/v1/transcribe",
                 "/v1/say", "/v1/check", "/v1/publish", "/v1/../etc", "/nothing"]

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-(2**63), 2**63),
                    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=30),
                    st.sampled_from(["cmd_vel", "arm", "people", "people_count", "/cmd_vel",
                                     "linear.x", "__import__('os').system('id')", "../status",
                     "people_count?x=1",
                                     "/9j/4AAQSkZJRg==", "UklGRiQAAABXQVZF", "x" * 5000]))
JSON = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=12), inner, max_size=4)),
    max_leaves=12)
TWIST = st.fixed_dictionaries({}, optional={
    "linear": st.dictionaries(st.sampled_from(["x", "y", "z", "w"]), JSON, max_size=3),
    "angular": st.dictionaries(st.sampled_from(["x", "y", "z"]), JSON, max_size=3)})
ARGUMENTS = st.one_of(
    st.dictionaries(st.sampled_from(["name", "route", "image", "audio", "question", "text",
                                     "target", "message"]), JSON, max_size=3),
    st.fixed_dictionaries({"target": st.sampled_from(["cmd_vel", "arm"]),
                           "message": st.one_of(TWIST, JSON)}))


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


@pytest.fixture(scope="module")
def domain() -> Iterator[None]:
    saved = dict(os.environ)
    os.environ.update(private_domain())
    yield
    os.environ.clear()
    os.environ.update(saved)


@pytest.fixture(scope="module")
def served(domain: None, tmp_path_factory: pytest.TempPathFactory, detector: RunningService
           ) -> Iterator[tuple[str, Path, subprocess.Popen[bytes]]]:
    """`oricf mcp --transport http` with tokens, its gateway's control API on a socket."""
    folder = tmp_path_factory.mktemp("fuzz_mcp")
    nowhere = f"127.0.0.1:{free_port()}"  # the language and speech models: absent
    config = pipeline_yaml(folder, detector.address, nowhere, nowhere)
    data = yaml.safe_load(config.read_text())
    data["control"] = {"listen": f"unix:{folder / 'control.sock'}"}
    for name in ("llm", "asr"):
        data["endpoints"][name]["deadline_ms"] = 500
    config.write_text(yaml.safe_dump(data))
    (folder / "tokens").write_text(TOKEN + "\n")
    port = free_port()
    with (folder / "mcp.log").open("wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "oricf", "mcp", "--config", str(config), "--transport",
             "http", "--listen", f"127.0.0.1:{port}", "--auth-token-file",
             str(folder / "tokens"), "--max-request-bytes", "65536"],
            stdout=log, stderr=subprocess.STDOUT, env=server_env(), start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while True:
            assert process.poll() is None, (folder / "mcp.log").read_text()
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline
                time.sleep(0.2)
        yield f"http://127.0.0.1:{port}/mcp", folder / "control.sock", process
    finally:
        process.terminate()
        process.wait(timeout=30)


@pytest.fixture(scope="module")
def driver(domain: None) -> Iterator[RosListener]:
    with ros_listener() as listener:
        yield listener


def within_policy(driver: RosListener) -> None:
    """Every command that reached the robot is inside the policy's bounds."""
    while not driver.twists.empty():
        twist = driver.twists.get_nowait()
        assert -0.3 <= twist.linear.x <= 0.3 and -0.5 <= twist.angular.z <= 0.5
        assert twist.linear.y == twist.linear.z == twist.angular.x == twist.angular.y == 0
    while not driver.arm.empty():
        assert 0.0 <= driver.arm.get_nowait().data <= 1.0


def lying_request(port: int, body: bytes, headers: dict[str, str]) -> int | None:
    """A POST whose Content-Length says 10 bytes whatever the body holds; the status the
    server answers, or None if it closed the connection (within 10 s either way)."""
    head = "".join(f"{k}: {v}\r\n" for k, v in headers.items())
    request = (f"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n{head}"
               f"Content-Length: 10\r\nConnection: close\r\n\r\n").encode() + body
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        try:
            sock.sendall(request)
            sock.shutdown(socket.SHUT_WR)
            reply = sock.recv(64)
        except OSError:
            return None
    parts = reply.split(b" ", 2)
    return int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else None


def still_serving(url: str) -> None:
    async def check() -> None:
        async with http_session(url, TOKEN) as session:
            look = await session.call_tool("look", {})
            assert look.structured_content is not None, look.content
            assert look.structured_content["counts"] == {"person": PEOPLE}

    deadline = time.monotonic() + 60
    while True:
        try:
            anyio.run(check)
            return
        except AssertionError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)


def test_hostile_http_requests(served: tuple[str, Path, subprocess.Popen[bytes]]) -> None:
    url, _, process = served
    port = int(url.split(":")[2].split("/")[0])
    still_serving(url)
    before = rss_mb(process.pid)
    headers = {"Authorization": f"Bearer {TOKEN}", "Accept": "application/json, "
               "text/event-stream", "Content-Type": "application/json"}
    client = httpx.Client(timeout=30)
    sent: list[bytes] = []
    message = st.fixed_dictionaries({"jsonrpc": st.sampled_from(["2.0", "1.0", 2]),
                                     "method": st.sampled_from(
                                         ["initialize", "tools/list", "tools/call",
                                          "resources/read", "resources/subscribe",
                                          "subscriptions/listen", "nothing", ""]),
                                     "params": JSON}, optional={"id": JSON})
    body = st.one_of(st.binary(max_size=300), message.map(lambda m: json.dumps(m).encode()),
                     st.just(b"[" * 100_000), st.just(b'{"a": "' + b"x" * 70_000 + b'"}'))

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(body, st.booleans())
    def hostile(data: bytes, lie: bool) -> None:
        sent.append(data)
        if lie:
            status = lying_request(port, data, headers)
            assert status is None or status < 500, status
            return
        response = client.post(url, content=data, headers=headers)
        assert response.status_code < 500, (response.status_code, response.text[:300])

    hostile()
    assert len(sent) >= EXAMPLES, len(sent)
    client.close()
    assert process.poll() is None
    still_serving(url)
    assert rss_mb(process.pid) - before < MAX_GROWTH_MB


def test_hostile_tool_arguments(served: tuple[str, Path, subprocess.Popen[bytes]],
                                driver: RosListener) -> None:
    url, _, process = served

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(st.tuples(st.sampled_from(sorted(TOOLS)), ARGUMENTS), min_size=1,
                    max_size=4))
    def hostile(calls: list[tuple[str, dict[str, Any]]]) -> None:
        async def scenario() -> None:
            async with http_session(url, TOKEN) as session:
                for tool, arguments in calls:
                    result = await session.call_tool(tool, arguments)
                    assert result.content  # a result, error or not: the server answered
                    answered.append(tool)

        anyio.run(scenario)
        within_policy(driver)

    answered: list[str] = []
    hostile()
    assert len(answered) >= EXAMPLES, len(answered)
    time.sleep(1.0)  # the deadman's zero commands
    within_policy(driver)
    assert process.poll() is None
    still_serving(url)


def test_hostile_control_requests(served: tuple[str, Path, subprocess.Popen[bytes]],
                                  driver: RosListener) -> None:
    url, sock, process = served
    client = httpx.Client(transport=httpx.HTTPTransport(uds=str(sock)),
                          base_url="http://gateway", timeout=30)

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.sampled_from(CONTROL_PATHS), st.sampled_from(["GET", "POST", "PUT"]),
           st.one_of(st.binary(max_size=200), JSON.map(lambda v: json.dumps(v).encode()),
                     ARGUMENTS.map(lambda v: json.dumps(v).encode())))
    def hostile(path: str, method: str, data: bytes) -> None:
        asked.append(path)
        response = client.request(method, path, content=data)
        assert response.status_code < 500, (path, response.status_code, response.text[:300])

    asked: list[str] = []
    hostile()
    assert len(asked) >= EXAMPLES, len(asked)
    oversized = client.post("/v1/detect", content=b'{"image": "' + b"A" * (13 << 20) + b'"}')
    assert oversized.status_code == 400 and "over" in oversized.json()["error"]
    client.close()
    time.sleep(1.0)
    within_policy(driver)
    assert process.poll() is None
    still_serving(url)


STDIO_MESSAGES = st.fixed_dictionaries(
    {"jsonrpc": st.sampled_from(["2.0", "1.0", 2, None]),
     "method": st.one_of(st.sampled_from(["initialize", "ping", "tools/list", "tools/call",
                                          "resources/list", "resources/read",
                                          "notifications/initialized", "nothing", ""]),
                         JSON)},
    optional={"id": JSON, "params": JSON})
WRONG_ID_REQUESTS = st.fixed_dictionaries(
    {"jsonrpc": st.just("2.0"), "method": st.sampled_from(["ping", "tools/list",
                                                          "notifications/initialized"]),
     "id": st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False, allow_infinity=False),
                     st.lists(SCALARS, max_size=2), st.dictionaries(st.text(max_size=5),
                                                                    SCALARS, max_size=2))})
STDIO_LINES = st.one_of(
    st.binary(max_size=300),
    STDIO_MESSAGES.map(lambda m: json.dumps(m).encode()),
    st.lists(STDIO_MESSAGES, max_size=3).map(lambda b: json.dumps(b).encode()),
    st.text(max_size=40).map(lambda t: json.dumps({"jsonrpc": "2.0", "id": 1, "method": t,
                                                   "params": {"name": "\ud800" + t}}).encode()),
    st.just(b"[" * 100_000), st.just(b'{"a": "' + b"x" * 70_000 + b'"}'),
    WRONG_ID_REQUESTS.map(lambda m: json.dumps(m).encode()),
    st.just(b'{"jsonrpc": "2.0", "id": 1, "method": "ping", "params": {"pad": "'
            + b"x" * MAX_STDIO_LINE_BYTES + b'"}}'))


def is_message(line: bytes) -> bool:
    """Whether the line is one JSON-RPC message that MCP takes (else an error is owed): not
    over the bound, read by the SDK, and not a request read as a notification because its id
    is neither an integer nor a string."""
    if len(line) > MAX_STDIO_LINE_BYTES:
        return False
    text = line.decode("utf-8", "replace")
    try:
        message = jsonrpc_message_adapter.validate_json(text, by_name=False)
    except ValidationError:
        return False
    return not (isinstance(message, JSONRPCNotification) and "id" in json.loads(text))


def test_hostile_stdio_lines(tmp_path: Path) -> None:
    """Each line that is no message gets its JSON-RPC error before the next ping's answer;
    everything written is JSON-RPC; the server stays up, in bounded memory."""
    config = approval_pipeline(tmp_path, approval_timeout_s=1.0)
    with RawStdio("--config", str(config), log=tmp_path / "mcp.log") as server:
        server.initialize()
        before = rss_mb(server.process.pid)
        pings: list[int] = []

        @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                  suppress_health_check=list(HealthCheck))
        @given(STDIO_LINES)
        def hostile(line: bytes) -> None:
            line = line.replace(b"\r", b" ").replace(b"\n", b" ")  # one line, as written
            server.write(line)
            ping = f"ping-{len(pings)}"
            pings.append(len(pings))
            server.send({"jsonrpc": "2.0", "id": ping, "method": "ping"})
            errors = []
            while (message := server.next()).get("id") != ping or "method" in message:
                assert message.get("jsonrpc") == "2.0", message
                if "error" in message:
                    errors.append(message["error"]["code"])
            assert "result" in message, message
            if not is_message(line):
                assert {-32600, -32700} & set(errors), (line[:200], errors)

        hostile()
        assert len(pings) >= EXAMPLES, len(pings)
        server.send({"jsonrpc": "2.0", "id": "last", "method": "tools/list"})
        assert server.reply("last")["result"]["tools"]
        assert rss_mb(server.process.pid) - before < MAX_GROWTH_MB
    assert "Traceback" not in (tmp_path / "mcp.log").read_text()


MCP_HEADERS = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json",
               "Accept": "application/json, text/event-stream"}
INITIALIZE = json.dumps({"jsonrpc": "2.0", "id": 1, "method": "initialize", "params": {
    "protocolVersion": "2025-06-18", "capabilities": {},
    "clientInfo": {"name": "raw", "version": "1"}}}).encode()


def answer_of(response: httpx.Response) -> dict[str, Any]:
    """The JSON-RPC answer in a response, plain JSON or one server-sent event."""
    assert response.status_code == 200, (response.status_code, response.text[:300])
    if response.headers.get("content-type", "").startswith("text/event-stream"):
        data = [line[5:] for line in response.text.splitlines() if line.startswith("data:")]
        return dict(json.loads(data[-1]))
    return dict(response.json())


def test_idle_connections_never_lock_a_client_out(
        served: tuple[str, Path, subprocess.Popen[bytes]]) -> None:
    """Seventy connections, silent or with headers never finished, at a server of 64: a
    client that asks is answered while they are still open (the header deadline, 10 s, has
    not cleared them); until the idle ones are a second old and may make room: 503."""
    url, _, process = served
    port = int(url.split(":")[2].split("/")[0])
    with ExitStack() as stack:
        idle = [stack.enter_context(socket.create_connection(("127.0.0.1", port), timeout=10))
                for _ in range(70)]
        for n, sock in enumerate(idle):
            if n % 2:
                sock.sendall(f"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode())
        started = time.monotonic()
        for _ in range(3):  # a fresh connection each time, to a server full of idle ones
            while True:
                with httpx.Client(timeout=30) as client:
                    response = client.post(url, content=INITIALIZE, headers=MCP_HEADERS)
                if response.status_code != 503 or time.monotonic() - started > 8:
                    break
                time.sleep(0.1)
            assert answer_of(response)["result"]["serverInfo"]["name"]
        assert sum(peer_closed(sock) for sock in idle) < len(idle) // 2  # no deadline yet
    assert process.poll() is None


BIG = b"1" + b"0" * 400


@pytest.mark.parametrize(("target", "message"), [
    ("arm", b'{"data": NaN}'), ("arm", b'{"data": Infinity}'), ("arm", b'{"data": 1e309}'),
    ("arm", b'{"data": ' + BIG + b"}"),
    ("cmd_vel", b'{"linear": {"x": -Infinity}}'), ("cmd_vel", b'{"linear": {"x": ' + BIG + b"}}"),
], ids=["nan", "infinity", "1e309", "400-digits", "twist-infinity", "twist-400-digits"])
def test_numbers_no_field_holds_are_refused_and_audited(
        served: tuple[str, Path, subprocess.Popen[bytes]], target: str,
        message: bytes) -> None:
    url, sock, process = served
    audit = sock.parent / "audit.jsonl"
    before = len(audit.read_text().splitlines())
    call = (b'{"jsonrpc": "2.0", "id": 2, "method": "tools/call", "params": {"name": '
            b'"publish", "arguments": {"target": "' + target.encode() + b'", "message": '
            + message + b"}}}")
    with httpx.Client(timeout=30) as client:
        opened = client.post(url, content=INITIALIZE, headers=MCP_HEADERS)
        answer_of(opened)
        session = {**MCP_HEADERS, "mcp-session-id": opened.headers.get("mcp-session-id", "")}
        client.post(url, headers=session, content=json.dumps(
            {"jsonrpc": "2.0", "method": "notifications/initialized"}).encode())
        result = answer_of(client.post(url, content=call, headers=session))["result"]
    assert result["isError"] is True, result
    text = result["content"][0]["text"]
    assert f"refused: {target}: " in text and "must be a finite number" in text
    entries = [json.loads(line) for line in audit.read_text().splitlines()[before:]]
    publishes = [e for e in entries if e["tool"] == "publish"]
    assert [e["outcome"] for e in publishes] == ["refused"], entries
    assert "must be a finite number" in publishes[0]["reason"]
    assert process.poll() is None
