"""`oricf mcp --attach`: a running `oricf gateway` serves its control API on a Unix socket
(and on loopback TCP with tokens); the MCP server attaches to it. The policy is enforced in
the gateway, so what the control API refuses no client can send."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import anyio
import mcp_types as types
import pytest
import yaml

from oricf.errors import InvalidInput, NotReady
from oricf.gateway.actuation.policy import Refused
from oricf.gateway.agents.resources import POLL_S, ResourceFeed, product_uri
from oricf.gateway.operations.client import ControlClient
from tests.gateway.agents.scene import PEOPLE, RosListener
from tests.gateway.agents.session import (
    server_env,
    stdio_session,
    text_of,
    wait_product,
    warm_up,
)
from tests.support.processes import free_port

APPROVER = "attach-approver-5"


@contextmanager
def gateway(config: Path, log: Path) -> Iterator[subprocess.Popen[bytes]]:
    with log.open("wb") as out:
        process = subprocess.Popen([sys.executable, "-m", "oricf", "gateway", "--config",
                                    str(config)], stdout=out, stderr=subprocess.STDOUT,
                                   env=server_env(), start_new_session=True)
    try:
        yield process
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)


def with_control(pipeline: Path, control: dict[str, Any], name: str) -> Path:
    data = yaml.safe_load(pipeline.read_text())
    data["control"] = control
    path = pipeline.parent / name
    path.write_text(yaml.safe_dump(data))
    return path


def wait_for(check: Any, process: subprocess.Popen[bytes], log: Path) -> None:
    deadline = time.monotonic() + 120
    while not check():
        assert process.poll() is None, log.read_text()
        assert time.monotonic() < deadline, log.read_text()
        time.sleep(0.2)


@pytest.fixture()
def socket_gateway(pipeline: Path, tmp_path: Path) -> Iterator[Path]:
    sock = tmp_path / "control.sock"
    (tmp_path / "approver.tokens").write_text(APPROVER + "\n")  # for the MCP server alone
    config = with_control(pipeline, {"listen": f"unix:{sock}", "approvers": {
        "file": str(tmp_path / "approver.tokens")}}, "attach_unix.yaml")
    log = tmp_path / "gateway.log"
    with gateway(config, log) as process:
        wait_for(sock.exists, process, log)
        yield sock


def test_attach_over_a_unix_socket(socket_gateway: Path, driver: RosListener) -> None:
    assert socket_gateway.stat().st_mode & 0o777 == 0o600

    async def approve(context: Any, params: types.ElicitRequestParams) -> types.ElicitResult:
        return types.ElicitResult(action="accept", content={"approve": True})

    async def scenario() -> None:
        async with stdio_session("--attach", f"unix:{socket_gateway}", "--token-file",
                                 str(socket_gateway.parent / "approver.tokens"),
                                 elicit=approve) as session:
            deadline = time.monotonic() + 60
            while (look := await session.call_tool("look", {})).is_error:
                assert time.monotonic() < deadline, text_of(look)
                await anyio.sleep(0.5)
            assert look.structured_content is not None
            assert look.structured_content["counts"] == {"person": PEOPLE}
            count = await session.call_tool("read_product", {"name": "people_count"})
            assert count.structured_content is not None
            assert count.structured_content["value"] == PEOPLE

            await warm_up(session, "arm", driver.arm)
            driver.drain()
            await anyio.sleep(0.2)
            arm = await session.call_tool("publish", {"target": "arm",
                                                      "message": {"data": 0.75}})
            assert not arm.is_error, text_of(arm)
            assert driver.arm.get(timeout=10).data == 0.75
            fast = await session.call_tool("publish", {"target": "cmd_vel",
                                                       "message": {"linear": {"x": 9}}})
            assert not fast.is_error  # clamped, in the gateway
            outside = await session.call_tool("publish", {"target": "lights",
                                                          "message": {"data": "on"}})
            assert outside.is_error and "not a target" in text_of(outside)

    anyio.run(scenario)
    # the control API's own client: the gateway refuses what the policy refuses
    client = ControlClient(f"unix:{socket_gateway}")
    with pytest.raises(Refused, match="approval"):
        client.publish("arm", {"data": 0.5}, approved=False)
    with pytest.raises(Refused, match="approval"):  # said, without an approver's token
        client.publish("arm", {"data": 0.5}, approved=True)
    with pytest.raises(Refused, match="outside"):
        client.publish("arm", {"data": 5.0}, approved=True)
    client.close()


def test_control_on_tcp_needs_tls_and_the_token(pipeline: Path, tmp_path: Path,
                                                certs: Path) -> None:
    tokens = tmp_path / "control.tokens"
    tokens.write_text("control-secret-9\n")
    port = free_port()
    config = with_control(pipeline, {
        "listen": f"127.0.0.1:{port}", "auth": {"file": str(tokens)},
        "tls": {"cert": str(certs / "server.pem"), "key": str(certs / "server.key")}},
        "attach_tcp.yaml")
    log = tmp_path / "gateway.log"
    with gateway(config, log) as process:
        address = f"https://127.0.0.1:{port}"
        anonymous = ControlClient(address, ca=certs / "ca.pem")

        def up() -> bool:
            try:
                anonymous.status()
            except NotReady as exc:
                return "bearer token" in str(exc)
            return False

        wait_for(up, process, log)
        wrong = tmp_path / "wrong"
        wrong.write_text("guess\n")
        with pytest.raises(NotReady, match="bearer token"):
            ControlClient(address, wrong, certs / "ca.pem").status()
        with pytest.raises(NotReady, match="CERTIFICATE_VERIFY_FAILED"):
            ControlClient(address, tokens).status()  # without the CA: not trusted
        status = ControlClient(address, tokens, certs / "ca.pem").status()
        assert "people" in status["routes"]
    assert "control-secret-9" not in log.read_text()


class CountedCalls:
    """The control client, counting the calls made through it."""

    def __init__(self, inner: ControlClient) -> None:
        self.inner = inner
        self.calls: Counter[str] = Counter()

    def __getattr__(self, name: str) -> Any:
        method = getattr(self.inner, name)

        def counted(*args: Any, **kwargs: Any) -> Any:
            self.calls[name] += 1
            return method(*args, **kwargs)
        return counted


def test_resources_are_polled_only_while_a_client_listens(socket_gateway: Path) -> None:
    gateway = CountedCalls(ControlClient(f"unix:{socket_gateway}"))
    feed = ResourceFeed(gateway)  # type: ignore[arg-type]
    events: list[Any] = []
    counts: dict[str, int] = {}

    async def scenario() -> None:
        async with feed.lifespan(None):  # type: ignore[arg-type]
            await anyio.sleep(4 * POLL_S)
            counts["idle"] = gateway.calls.total()
            stop = feed.bus.subscribe(events.append)
            deadline = time.monotonic() + 60
            while not any(getattr(e, "uri", "") == "oricf://products/people_count"
                          for e in events):
                assert time.monotonic() < deadline, "no update of people_count"
                await anyio.sleep(0.1)
            stop()
            await anyio.sleep(POLL_S)  # a poll under way when the listener left
            counts["left"] = gateway.calls.total()
            await anyio.sleep(4 * POLL_S)
            counts["after"] = gateway.calls.total()

    anyio.run(scenario)
    gateway.inner.close()
    assert counts["idle"] == 0
    assert counts["after"] == counts["left"] > 0
    # one poll = two control calls (the products with their values, the routes)
    assert gateway.calls["read_product"] == 0
    assert abs(gateway.calls["products"] - gateway.calls["status"]) <= 1


ODD_PRODUCT = "people/count?x=1#y%2F"  # in a URL: a slash, a query, a fragment, an escape
NOT_PRODUCTS = ["../status", "../policy", "../look", "people_count?x=1", "people_count#x",
                "people_count/", "..", ".", "%2e%2e%2fstatus", "people/count",
                "people_count/../people_count", "people_count\r\nX: y"]


@pytest.fixture()
def odd_gateway(pipeline: Path, tmp_path: Path) -> Iterator[Path]:
    """A gateway on a Unix socket whose people route also writes ODD_PRODUCT."""
    sock = tmp_path / "control.sock"
    config = with_control(pipeline, {"listen": f"unix:{sock}"}, "attach_odd.yaml")
    data = yaml.safe_load(config.read_text())
    data["routes"]["people"]["outputs"].append({"product": ODD_PRODUCT, "from": "count"})
    config.write_text(yaml.safe_dump(data))
    log = tmp_path / "gateway.log"
    with gateway(config, log) as process:
        wait_for(sock.exists, process, log)
        yield sock


def test_attached_product_names_are_checked_as_in_process(odd_gateway: Path) -> None:
    """What is not a data product is refused as the gateway itself refuses it, never read
    as another endpoint of the control API; a product's name reaches the gateway whole."""
    known = ", ".join(sorted([ODD_PRODUCT, "people_count", "transcript"]))

    async def scenario() -> None:
        async with stdio_session("--attach", f"unix:{odd_gateway}") as session:
            await wait_product(session, "people_count")
            for name in NOT_PRODUCTS:
                result = await session.call_tool("read_product", {"name": name})
                assert result.is_error, (name, result.structured_content)
                assert text_of(result).endswith(
                    f": no data product {name!r} (products: {known})"), text_of(result)
            odd = await wait_product(session, ODD_PRODUCT)
            assert odd["name"] == ODD_PRODUCT and odd["value"] == PEOPLE
            uri = product_uri(ODD_PRODUCT)  # its resource: the name escaped in the URI
            assert uri == "oricf://products/people%2Fcount%3Fx%3D1%23y%252F"
            read = await session.read_resource(uri)
            text = read.contents[0]
            assert isinstance(text, types.TextResourceContents), text
            assert json.loads(text.text)["name"] == ODD_PRODUCT

    anyio.run(scenario)
    client = ControlClient(f"unix:{odd_gateway}")
    for name in NOT_PRODUCTS:
        with pytest.raises(InvalidInput, match=r"^no data product "):
            client.read_product(name)
    assert client.read_product(ODD_PRODUCT)["value"] == PEOPLE
    client.close()
