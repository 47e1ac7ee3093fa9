"""The gateway's control API against hostile clients, on real sockets: a real pipeline in
this process with an agent policy (its topics heard by a real rclpy subscriber, its text
target read by a real TCP client), served on loopback TCP with tokens and on a Unix socket.

- Silent connections and half-sent headers never lock a client out: one that asks is
  answered, not 503, long before the header deadline would close them; a connection with
  no whole request is closed at that deadline; a body that never arrives is answered 408.
- `approved: true` is taken only from a client holding an approver's token: a publishing
  client that says it is refused, and the refusal is audited.
- NaN, infinities, 1e309 and 400-digit integers are refused with the reason (never 500), and
  the audit log records the refusal.
- Text sent to a display's channel reaches it without raw control characters.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest

from oricf.gateway.config import parse_pipeline
from oricf.gateway.shells.embedded import EmbeddedGateway
from tests.gateway.agents.scene import ARM_TOPIC, RosListener, ros_listener
from tests.support.processes import free_port
from tests.support.sockets import peer_closed

TOKEN = "control-publisher-3"
APPROVER = "control-approver-8"
SILENT = 70  # more than the API's 64 connections
HEADER_TIMEOUT_S = 30.0  # on TCP: far beyond any wait here, so only room explains an answer
UNIX_HEADER_TIMEOUT_S = 4.0  # on the Unix socket: the deadline itself is tested there
BODY_TIMEOUT_S = 2.0
WAIT_S = 10.0


@dataclass
class Served:
    tcp: str
    unix: Path
    audit: Path
    display: str  # host:port of the display's text channel


def pipeline(folder: Path, listen: str) -> dict[str, Any]:
    """A typed-question route (its model absent: the control API still serves), an agent
    policy with an arm that needs approval, a counter and a display, and `control:`."""
    (folder / "tokens").write_text(TOKEN + "\n")
    (folder / "approvers").write_text(APPROVER + "\n")
    return {
        "endpoints": {"llm": {"address": f"127.0.0.1:{free_port()}", "deadline_ms": 500}},
        "channels": {"questions": {"listen": f"127.0.0.1:{free_port()}"},
                     "robot_says": {"listen": f"127.0.0.1:{free_port()}"}},
        "routes": {"ask": {"input": {"text": "questions"},
                           "call": {"service": "llm", "method": "Generate",
                                    "prompt": "{text}"},
                           "outputs": [{"text": "questions", "from": "answer"}]}},
        "agent": {"audit": str(folder / "audit.jsonl"), "targets": {
            "arm_lift": {"topic": ARM_TOPIC, "type": "std_msgs/Float64",
                         "bounds": {"data": [0.0, 1.0]}, "max_rate_hz": 1000,
                         "approval": "elicit"},
            "count": {"topic": "/control_test/count", "type": "std_msgs/Int32",
                      "bounds": {"data": [-10, 10]}, "max_rate_hz": 1000},
            "display": {"channel": "robot_says", "max_rate_hz": 1000}}},
        "control": {"listen": listen, "auth": {"file": str(folder / "tokens")},
                    "approvers": {"file": str(folder / "approvers")},
                    "header_timeout_s": HEADER_TIMEOUT_S, "body_timeout_s": BODY_TIMEOUT_S},
    }


@pytest.fixture(scope="module")
def driver(ros_env: dict[str, str]) -> Iterator[RosListener]:
    with ros_listener() as listener:
        yield listener


@pytest.fixture(scope="module")
def served(driver: RosListener, tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[Served]:
    """The same pipeline twice: its control API on TCP, and on a Unix socket (where no
    token is needed, but only an approver's token approves)."""
    folder = tmp_path_factory.mktemp("control")
    port = free_port()
    tcp = pipeline(folder, f"127.0.0.1:{port}")
    sock = folder / "control.sock"
    unix = {**tcp, "control": {"listen": f"unix:{sock}",
                               "approvers": {"file": str(folder / "approvers")},
                               "header_timeout_s": UNIX_HEADER_TIMEOUT_S},
            "channels": {"questions": {"listen": f"127.0.0.1:{free_port()}"},
                         "robot_says": {"listen": f"127.0.0.1:{free_port()}"}},
            "agent": {**tcp["agent"], "audit": str(folder / "audit_unix.jsonl")}}
    embedded = [EmbeddedGateway(parse_pipeline(data, f"test pipeline {n}", folder))
              for n, data in enumerate([tcp, unix])]
    try:
        for one in embedded:
            one.start()
        driver.wait_publisher(ARM_TOPIC)
        yield Served(f"http://127.0.0.1:{port}", sock, folder / "audit.jsonl",
                     tcp["channels"]["robot_says"]["listen"])
    finally:
        for one in embedded:
            one.stop()


def client(served: Served, token: str | None = TOKEN) -> httpx.Client:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.Client(base_url=served.tcp, headers=headers, timeout=10)


def unix_client(served: Served, token: str | None = None) -> httpx.Client:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.Client(transport=httpx.HTTPTransport(uds=str(served.unix)),
                        base_url="http://gateway", headers=headers, timeout=10)


def audited(path: Path, target: str) -> list[dict[str, Any]]:
    return [entry for line in path.read_text().splitlines()
            if (entry := json.loads(line)).get("target") == target]


def tcp_socket(served: Served) -> socket.socket:
    return socket.create_connection(("127.0.0.1", int(served.tcp.rsplit(":", 1)[1])),
                                    timeout=10)


def unix_socket(served: Served) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(10)
    sock.connect(str(served.unix))
    return sock


HALF_HEADERS = b"GET /v1/status HTTP/1.1\r\nHost: x\r\n"  # the headers never end


def answered_among_idle(http: httpx.Client, idle: list[socket.socket]) -> None:
    """A fresh connection's request is answered, while the idle connections stay open but
    for the few closed to make room (those less than a second old may not go: until then,
    503)."""
    deadline = time.monotonic() + WAIT_S
    while True:
        response = http.get("/v1/status", headers={"Connection": "close"})
        if response.status_code != 503 or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    assert response.status_code == 200, response.text
    assert "ask" in response.json()["routes"]
    assert sum(peer_closed(sock) for sock in idle) < len(idle) // 2  # no deadline cleared them


@pytest.mark.parametrize("where", ["tcp", "unix"])
@pytest.mark.parametrize("first_bytes", [b"", HALF_HEADERS], ids=["silent", "half-headers"])
def test_idle_connections_never_lock_a_client_out(served: Served, where: str,
                                                  first_bytes: bytes) -> None:
    connect = (lambda: tcp_socket(served)) if where == "tcp" else (lambda: unix_socket(served))
    with ExitStack() as stack:
        idle = [stack.enter_context(connect()) for _ in range(SILENT)]
        for sock in idle:
            sock.sendall(first_bytes)
        http = stack.enter_context(client(served) if where == "tcp" else unix_client(served))
        for _ in range(3):  # each time a fresh connection, at a server full of idle ones
            answered_among_idle(http, idle)


def test_a_connection_without_a_whole_request_is_closed(served: Served) -> None:
    for first_bytes in (b"", HALF_HEADERS):
        with unix_socket(served) as sock:
            sock.sendall(first_bytes)
            sock.settimeout(UNIX_HEADER_TIMEOUT_S + WAIT_S)
            assert sock.recv(4096) == b""  # closed by the server, without an answer


def test_a_body_that_never_arrives_is_answered_408(served: Served) -> None:
    with tcp_socket(served) as sock:
        sock.sendall(f"POST /v1/check HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}"
                     f"\r\nContent-Length: 100\r\n\r\n{{\"target\"".encode())
        sock.settimeout(BODY_TIMEOUT_S + WAIT_S)
        reply = sock.recv(4096)
    assert reply.startswith(b"HTTP/1.1 408"), reply[:200]
    assert f"did not arrive within {BODY_TIMEOUT_S:g} s".encode() in reply


def test_approval_said_by_a_publishing_client_is_refused(served: Served,
                                                          driver: RosListener) -> None:
    forged = {"target": "arm_lift", "message": {"data": 0.5}, "approved": True}
    audits = (served.audit, served.audit.with_name("audit_unix.jsonl"))
    before = [len(audited(path, "arm_lift")) for path in audits]
    with client(served) as publisher, unix_client(served) as local:
        for http in (publisher, local):
            response = http.post("/v1/publish", json=forged)
            assert response.status_code == 403, response.text
            assert "needs a person's approval" in response.json()["error"]
    for path, seen in zip(audits, before, strict=True):
        refusals = audited(path, "arm_lift")[seen:]
        assert [e["outcome"] for e in refusals] == ["refused"]
        assert "approval" in refusals[0]["reason"]
    # the approver's token (the MCP server that asked its user) is taken, on both sockets
    with client(served, APPROVER) as approver, unix_client(served, APPROVER) as local:
        for http, value in ((approver, 0.25), (local, 0.75)):
            response = http.post("/v1/publish", json={**forged, "message": {"data": value}})
            assert response.status_code == 200, response.text
            assert driver.arm.get(timeout=WAIT_S).data == value
    assert driver.arm.empty()  # the forged 0.5 never went out
    with client(served, "guess") as stranger:
        assert stranger.post("/v1/publish", json=forged).status_code == 401


BIG = "1" + "0" * 400
HOSTILE_NUMBERS = [  # target, message, the reason, the value as the audit records it
    ("arm_lift", b'{"data": NaN}', "data must be a finite number", "NaN"),
    ("arm_lift", b'{"data": Infinity}', "data must be a finite number", "Infinity"),
    ("arm_lift", b'{"data": -Infinity}', "data must be a finite number", "-Infinity"),
    ("arm_lift", b'{"data": 1e309}', "data must be a finite number", "Infinity"),
    ("arm_lift", b'{"data": ' + BIG.encode() + b"}", "data must be a finite number", BIG),
    ("count", b'{"data": ' + BIG.encode() + b"}", "data must be a 32-bit integer", BIG),
    ("count", b'{"data": NaN}', "data must be a 32-bit integer", "NaN"),
    ("count", b'{"data": 4294967296}', "data must be a 32-bit integer", 4294967296),
]


@pytest.mark.parametrize(("target", "message", "why", "recorded"), HOSTILE_NUMBERS)
def test_numbers_beyond_the_fields_type_are_refused_and_audited(
        served: Served, target: str, message: bytes, why: str, recorded: Any) -> None:
    before = len(audited(served.audit, target))
    body = b'{"target": "' + target.encode() + b'", "message": ' + message + b"}"
    with client(served, APPROVER) as http:
        for path in ("/v1/check", "/v1/publish"):
            response = http.post(path, content=body)
            assert response.status_code == 403, (path, response.status_code, response.text)
            assert why in response.json()["error"]
    entries = audited(served.audit, target)[before:]
    assert [e["outcome"] for e in entries] == ["refused", "refused"]
    assert all(why in e["reason"] for e in entries)
    assert [e["message"]["data"] for e in entries] == [recorded, recorded]


def test_control_characters_never_reach_the_display_raw(served: Served) -> None:
    text = "Hi\x1b[2J\x1b]0;owned\x07 there\x00!\tok\x9b31m\x7f"
    host, port = served.display.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as display, \
            client(served) as http:
        display.settimeout(0.5)
        received = b""
        deadline = time.monotonic() + WAIT_S
        while b"\n" not in received:  # until the channel has taken the display in
            response = http.post("/v1/publish", json={"target": "display",
                                                      "message": {"data": text}})
            assert response.status_code == 200, response.text
            try:
                received += display.recv(4096)
            except TimeoutError:
                assert time.monotonic() < deadline, "nothing reached the display"
    assert received.split(b"\n")[0] == \
        b"Hi\\x1b[2J\\x1b]0;owned\\x07 there\\x00!\tok\\x9b31m\\x7f"
