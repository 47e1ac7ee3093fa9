"""The control API's paths are written once (oricf.gateway.operations.api.PATHS): the server
serves every operation at its path and the client's every operation reaches it, over a real
localhost server. The gateway behind the server only records which operation it was asked
for: the paths are under test here, not the pipeline (tests/agents drive a real one)."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from oricf.gateway.api.server import ControlServer, control_app
from oricf.gateway.listeners import ControlConfig
from oricf.gateway.operations.api import PATHS, Json, Operations
from oricf.gateway.operations.client import ControlClient

TOKEN = "s3cret"


class Recorded:
    """Operations that answer with their own name, remembering what they were asked."""

    def __init__(self) -> None:
        self.asked: list[str] = []

    def __getattr__(self, operation: str) -> Callable[..., Any]:
        if operation not in PATHS:
            raise AttributeError(operation)

        def answer(*args: Any, **kwargs: Any) -> Any:
            self.asked.append(operation)
            if operation == "products":
                return [{"name": "people_count"}]
            if operation == "look":
                return {"operation": operation}, b"jpeg"
            return {"operation": operation}

        return answer


# Each operation as a client calls it.
CALLS: dict[str, Callable[[ControlClient], Any]] = {
    "products": lambda c: c.products(),
    "read_product": lambda c: c.read_product("people_count"),
    "look": lambda c: c.look("people"),
    "status": lambda c: c.status(),
    "policy": lambda c: c.policy(),
    "detect": lambda c: c.detect(b"jpeg", "people"),
    "infer": lambda c: c.infer("classes", b"jpeg"),
    "ask": lambda c: c.ask("how many?"),
    "transcribe": lambda c: c.transcribe(b"wav"),
    "say": lambda c: c.say("hello"),
    "check": lambda c: c.check("base", {"x": 1}),
    "publish": lambda c: c.publish("base", {"x": 1}),
}


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[ControlClient, Recorded]]:
    tokens = tmp_path / "tokens"
    tokens.write_text(f"{TOKEN}\n")
    gateway = Recorded()
    server = ControlServer(ControlConfig.model_validate(
        {"listen": "127.0.0.1:0", "auth": {"file": str(tokens)}}), gateway)  # type: ignore[arg-type]
    server.start()
    client = ControlClient(server.address, token_file=tokens)
    try:
        yield client, gateway
    finally:
        client.close()
        server.close()


def test_every_operation_has_one_path() -> None:
    operations = {name for name, _ in inspect.getmembers(Operations, inspect.isfunction)
                  if not name.startswith("_")} - {"close"}
    assert set(PATHS) == operations
    assert len({(api.http, api.path) for api in PATHS.values()}) == len(PATHS)


def test_the_server_serves_exactly_the_paths(tmp_path: Path) -> None:
    config = ControlConfig.model_validate({"listen": f"unix:{tmp_path / 'control.sock'}"})
    app = control_app(Recorded(), config)  # type: ignore[arg-type]
    served = {(route.path, frozenset(route.methods or ())) for route in app.routes}  # type: ignore[attr-defined]
    expected = {(api.path, frozenset({api.http, "HEAD"} if api.http == "GET" else {api.http}))
                for api in PATHS.values()}
    assert served == expected


def test_each_client_operation_reaches_its_own_on_the_server(
        served: tuple[ControlClient, Recorded]) -> None:
    client, gateway = served
    assert set(CALLS) == set(PATHS)
    for operation, call in CALLS.items():
        gateway.asked.clear()
        answer: Json | tuple[Json, bytes] | list[Json] = call(client)
        assert gateway.asked[-1] == operation
        if operation == "look":
            assert answer == ({"operation": "look"}, b"jpeg")
        elif operation != "products":
            assert answer == {"operation": operation}
