"""`oricf mcp` over stdio against what a client should not send: each malformed line gets its
JSON-RPC error (with the request's id where one can be read) and the server goes on serving,
a request whose id is neither an integer nor a string included; a line longer than the bound
is answered without being held in memory; an approval by elicitation that is never answered
ends the call at the target's approval_timeout_s, refused and audited. A real `oricf mcp`
process; no model is needed."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import anyio
import mcp_types as types

from tests.gateway.agents.raw import RawStdio, approval_pipeline
from tests.gateway.agents.session import stdio_session, text_of

INVALID_REQUEST, PARSE_ERROR = -32600, -32700
MAX_LINE_BYTES = 16 * 1024 * 1024
MAX_PEAK_GROWTH_MB = 64

# (the line as the client writes it, the error code owed, the id the answer carries)
MALFORMED: list[tuple[bytes, int, Any]] = [
    (b'{"jsonrpc": "2.0", "id": 1}', INVALID_REQUEST, 1),  # no method
    (b'{"jsonrpc": "1.0", "id": 2, "method": "tools/list"}', INVALID_REQUEST, 2),
    (b'{"jsonrpc": "2.0", "id": 3, "method": 5}', INVALID_REQUEST, 3),
    (b'{"jsonrpc": "2.0", "id": 4, "method": "tools/call", "params": [1, 2]}',
     INVALID_REQUEST, 4),
    (b'[{"jsonrpc": "2.0", "id": 5, "method": "tools/list"}]', INVALID_REQUEST, None),
    (b'{"jsonrpc": "2.0", "id": 6, "method": "tools/call", "params": {"name": "\\ud800", '
     b'"arguments": {}}}', INVALID_REQUEST, 6),  # a lone surrogate in a tool's name
    (b'{"jsonrpc": "2.0", "id": 7, "method": "tools/call", "params": {"name": '
     b'"read_product", "arguments": {"name": "x\\udc80"}}}', INVALID_REQUEST, 7),
    (b'{"jsonrpc": "2.0", "id": "\\ud800", "method": "tools/list"}', INVALID_REQUEST, None),
    (b'{"jsonrpc": "2.0", "method": 5}', INVALID_REQUEST, None),
    (b'{"jsonrpc": "2.0", "id": 10, "method": "tools/list", "params": "all"}',
     INVALID_REQUEST, 10),
    (b'{"jsonrpc": "2.0", "id": 11, "method": "tools/list"', PARSE_ERROR, None),
    (b"not json at all", PARSE_ERROR, None),
    (b"[]", INVALID_REQUEST, None),
    (b"42", INVALID_REQUEST, None),
]


def test_each_malformed_message_is_answered_and_serving_goes_on(tmp_path: Path) -> None:
    config = approval_pipeline(tmp_path)
    with RawStdio("--config", str(config), log=tmp_path / "mcp.log") as server:
        server.initialize()
        for line, code, request_id in MALFORMED:
            server.write(line)
            answer = server.next()
            assert answer.get("id", "absent") == request_id, (line, answer)
            assert answer["error"]["code"] == code, (line, answer)
            assert "result" not in answer
        # bytes that are not UTF-8 in a name: read as U+FFFD, an unknown product, answered
        server.write(b'{"jsonrpc": "2.0", "id": 20, "method": "tools/call", "params": '
                     b'{"name": "read_product", "arguments": {"name": "\xed\xa0\x80"}}}')
        unknown = server.reply(20)
        assert unknown["result"]["isError"] is True, unknown
        assert "no data product" in json.dumps(unknown["result"]["content"])
        server.send({"jsonrpc": "2.0", "id": 21, "method": "tools/list"})
        tools = server.reply(21)["result"]["tools"]
        assert "publish" in {tool["name"] for tool in tools}
    log = (tmp_path / "mcp.log").read_text()
    assert "Traceback" not in log
    assert log.count("a malformed message answered") >= 1


# ids that JSON-RPC 2.0 does not allow in a request (true, an object, a list) or that MCP does
# not (null, a fraction): a request with one was read as a notification and never answered
WRONG_IDS = [b"true", b"false", b"null", b"1.5", b"2.0", b"-0.0", b"1e3", b'{"n": 1}', b"[1]",
             b"[]"]


def test_a_request_whose_id_is_no_request_id_is_answered(tmp_path: Path) -> None:
    config = approval_pipeline(tmp_path)
    with RawStdio("--config", str(config), log=tmp_path / "mcp.log") as server:
        server.initialize()
        for n, wrong in enumerate(WRONG_IDS):
            for method in (b"tools/list", b"notifications/initialized"):
                server.write(b'{"jsonrpc": "2.0", "id": ' + wrong + b', "method": "' + method
                             + b'"}')
                server.send({"jsonrpc": "2.0", "id": f"ping-{n}", "method": "ping"})
                answer = server.next()  # the error comes before the ping's answer
                assert answer.get("id", "absent") is None, (wrong, method, answer)
                assert answer["error"]["code"] == INVALID_REQUEST, (wrong, answer)
                assert "id" in answer["error"]["message"], answer
                assert "result" in server.reply(f"ping-{n}")
        server.send({"jsonrpc": "2.0", "id": 0, "method": "tools/list"})  # 0 is an id
        assert server.reply(0)["result"]["tools"]
    assert "Traceback" not in (tmp_path / "mcp.log").read_text()


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM")


def write_long_line(process: subprocess.Popen[bytes], total_bytes: int) -> None:
    """A request with params so long that reading the whole line builds millions of objects,
    written a mebibyte at a time."""
    assert process.stdin is not None
    head = b'{"jsonrpc": "2.0", "id": "long", "method": "ping", "params": {"pad": ['
    process.stdin.write(head)
    chunk = b"0," * (512 * 1024)
    for _ in range((total_bytes - len(head)) // len(chunk)):
        process.stdin.write(chunk)
    process.stdin.write(b"0]}}\n")
    process.stdin.flush()


def test_a_line_over_the_bound_is_answered_and_not_held(tmp_path: Path) -> None:
    config = approval_pipeline(tmp_path)
    with RawStdio("--config", str(config), log=tmp_path / "mcp.log") as server:
        server.initialize()
        before = peak_rss_mb(server.process.pid)
        write_long_line(server.process, 20 * 1024 * 1024)
        server.send({"jsonrpc": "2.0", "id": "after", "method": "ping"})
        answer = server.next()
        assert answer.get("id", "absent") is None, answer
        assert answer["error"]["code"] == INVALID_REQUEST, answer
        assert answer["error"]["message"].endswith(
            f"line too long ({MAX_LINE_BYTES} bytes at most)"), answer
        assert "result" in server.reply("after")
        growth = peak_rss_mb(server.process.pid) - before
        assert growth < MAX_PEAK_GROWTH_MB, growth
        # a line of exactly the bound is read whole
        head = b'{"jsonrpc": "2.0", "id": "full", "method": "ping", "params": {"pad": "'
        tail = b'"}}'
        server.write(head + b"x" * (MAX_LINE_BYTES - len(head) - len(tail)) + tail)
        assert "result" in server.reply("full")
    assert "Traceback" not in (tmp_path / "mcp.log").read_text()


def test_an_unanswered_approval_is_refused_at_its_deadline(tmp_path: Path) -> None:
    config = approval_pipeline(tmp_path, approval_timeout_s=1.0)
    asked: list[str] = []

    async def never_answers(context: Any, params: types.ElicitRequestParams
                            ) -> types.ElicitResult:
        asked.append(params.message)
        await anyio.sleep_forever()
        raise AssertionError("unreachable")

    async def scenario() -> None:
        async with stdio_session("--config", str(config), elicit=never_answers) as session:
            with anyio.fail_after(60):  # without a deadline the call would never end
                sent = await session.call_tool("publish", {"target": "display",
                                                           "message": {"data": "open"}})
            assert sent.is_error
            assert text_of(sent).endswith("refused: display: not approved (no answer within 1 s)")
            assert asked and "display" in asked[0]
            listed = await session.call_tool("list_products", {})  # still serving
            assert not listed.is_error, text_of(listed)

    anyio.run(scenario)
    audit = [json.loads(line) for line in (tmp_path / "audit.jsonl").read_text().splitlines()]
    refused = [a for a in audit if a["tool"] == "publish" and a["outcome"] == "refused"]
    assert len(refused) == 1, audit
    assert refused[0]["target"] == "display"
    assert refused[0]["reason"] == "display: not approved (no answer within 1 s)"
    assert not any(a["outcome"] in ("sent", "clamped") for a in audit)

