"""The control API over HTTP: JSON on loopback TCP or a Unix socket (mode 0600), bearer
tokens, TLS; Starlette on uvicorn in a thread of its own. Its paths are the operations'
(oricf.gateway.operations.api.PATHS, which the client calls too):

    GET  /v1/products            GET /v1/products/{name}      GET /v1/look?route=R
    GET  /v1/status              GET /v1/policy
    POST /v1/detect {image, route}   /v1/infer {route, image}   /v1/ask {question}
         /v1/transcribe {audio}      /v1/say {text}
         /v1/check {target, message} /v1/publish {target, message, approved}

Images and audio travel base64. Errors: {"error": why, "kind": InvalidInput | NotReady |
Refused | Internal} with 400 (408 for a body that does not arrive in time), 503, 403 or
500; nothing internal is told.

`approved: true` counts only on a request that carries a token of `control.approvers` (the
MCP server that asked its user by elicitation): any other client's claim is not taken, so a
target that needs approval refuses it. Connections: a deadline for request headers and room
for a client that asks (oricf.http_connections), a deadline for request bodies.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import json
import logging
import os
import socket
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import JSONResponse
from starlette.routing import Route
from starlette.types import ASGIApp

from oricf.errors import ConfigError, InvalidInput, NotReady, OricfError
from oricf.gateway.actuation.policy import Refused
from oricf.gateway.listeners import ControlConfig
from oricf.gateway.operations.api import PATHS, Json, Operations
from oricf.hosts import Address
from oricf.http_connections import guarded_h11
from oricf.tokens import APPROVER, BearerTokens

log = logging.getLogger(__name__)

STATUS = {"InvalidInput": 400, "Refused": 403, "NotReady": 503}


class LateBody(InvalidInput):
    """A request body that did not arrive within control.body_timeout_s (408)."""


def error_kind(exc: Exception) -> str:
    for kind in (Refused, InvalidInput, NotReady):
        if isinstance(exc, kind):
            return kind.__name__
    return "InvalidInput" if isinstance(exc, OricfError) else "Internal"


def error_response(request: Request, exc: Exception) -> JSONResponse:
    kind = error_kind(exc)
    if kind == "Internal":
        log.exception("control API %s failed", request.url.path)
        return JSONResponse({"error": "internal error", "kind": kind}, 500)
    status = 408 if isinstance(exc, LateBody) else STATUS[kind]
    return JSONResponse({"error": str(exc), "kind": kind}, status)


def b64(data: Any, what: str) -> bytes:
    if not isinstance(data, str):
        raise InvalidInput(f"{what}: base64 text expected")
    try:
        return base64.b64decode(data, validate=True)
    except (binascii.Error, ValueError):
        raise InvalidInput(f"{what}: not valid base64") from None


async def read_body(request: Request, max_bytes: int, timeout_s: float) -> bytes:
    """The whole body, within the byte limit and the deadline."""
    chunks: list[bytes] = []
    size = 0
    deadline = time.monotonic() + timeout_s
    stream = request.stream().__aiter__()
    while True:
        try:
            chunk = await asyncio.wait_for(stream.__anext__(), deadline - time.monotonic())
        except StopAsyncIteration:
            return b"".join(chunks)
        except asyncio.TimeoutError:
            raise LateBody(f"the request body did not arrive within {timeout_s:g} s") from None
        size += len(chunk)
        if size > max_bytes:
            raise InvalidInput(f"request body over {max_bytes:,} bytes")
        chunks.append(chunk)


def control_app(gateway: Operations, config: ControlConfig) -> Starlette:
    async def body(request: Request) -> Json:
        raw = await read_body(request, config.max_body_bytes, config.body_timeout_s)
        try:
            data = json.loads(raw or b"{}")
        except (ValueError, RecursionError):
            raise InvalidInput("request body is not JSON") from None
        if not isinstance(data, dict):
            raise InvalidInput("request body must be a JSON object")
        return data

    def endpoint(work: Callable[[Request, Json], Any], post: bool = False
                 ) -> Callable[[Request], Awaitable[JSONResponse]]:
        async def handle(request: Request) -> JSONResponse:
            from starlette.concurrency import run_in_threadpool

            try:
                data = await body(request) if post else {}
                return JSONResponse(await run_in_threadpool(work, request, data))
            except Exception as exc:
                return error_response(request, exc)
        return handle

    def publish(request: Request, data: Json) -> Json:
        target = str(data.get("target", ""))
        claimed = data.get("approved") is True
        approved = claimed and bool(request.scope.get(APPROVER))
        if claimed and not approved:  # the policy refuses it, and the audit says so
            log.warning("control API: a publish to %.100r said it was approved without an "
                        "approver's token (control.approvers); not taken", target)
        return gateway.publish(target, data.get("message"), approved)

    def look(request: Request, _: Json) -> Json:
        info, jpeg = gateway.look(request.query_params.get("route"))
        return {**info, "image": base64.b64encode(jpeg).decode()}

    g = gateway
    # Each operation's handler, served at its path in PATHS.
    work: dict[str, Callable[[Request, Json], Any]] = {
        "products": lambda r, d: {"products": g.products()},
        "read_product": lambda r, d: g.read_product(r.path_params["name"]),
        "look": look,
        "status": lambda r, d: g.status(),
        "policy": lambda r, d: g.policy(),
        "detect": lambda r, d: g.detect(b64(d.get("image"), "image"), d.get("route")),
        "infer": lambda r, d: g.infer(
            str(d.get("route", "")),
            None if d.get("image") is None else b64(d.get("image"), "image"),
            d.get("tensors")),
        "ask": lambda r, d: g.ask(d.get("question")),  # type: ignore[arg-type]
        "transcribe": lambda r, d: g.transcribe(b64(d.get("audio"), "audio")),
        "say": lambda r, d: g.say(d.get("text")),  # type: ignore[arg-type]
        "check": lambda r, d: g.check(str(d.get("target", "")), d.get("message")),
        "publish": publish,
    }
    routes = [Route(api.path, endpoint(work[name], post=api.http == "POST"), methods=[api.http])
              for name, api in PATHS.items()]
    return Starlette(routes=routes)


class ControlServer:
    """start() binds (raising if it cannot) and serves in a thread; close() stops it."""

    def __init__(self, config: ControlConfig, gateway: Operations) -> None:
        self.config = config
        self.gateway = gateway
        self.address = ""
        self._server: Any = None
        self._thread: threading.Thread | None = None

    def _socket(self) -> socket.socket:
        listen = self.config.listen
        if not isinstance(listen, Address):
            path = listen.path
            if path.is_socket():
                path.unlink()  # left by a gateway that did not stop cleanly
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            old = os.umask(0o177)  # born 0600: only this user may connect
            try:
                sock.bind(str(path))
            finally:
                os.umask(old)
            self.address = str(listen)
            return sock
        family = socket.AF_INET6 if ":" in listen.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((listen.host, listen.port))
        scheme = "https" if self.config.tls else "http"
        bound = Address(listen.host, sock.getsockname()[1])  # an IPv6 host in brackets
        self.address = f"{scheme}://{bound}"
        return sock

    def _app(self) -> ASGIApp:
        config = self.config
        tokens = tuple(t.encode() for t in config.auth.tokens()) if config.auth else ()
        approvers = (tuple(t.encode() for t in config.approvers.tokens())
                     if config.approvers else ())
        if set(tokens) & set(approvers):
            raise ConfigError("control.approvers: a token of control.auth is also an "
                              "approver's; every client holding it could approve")
        return BearerTokens(control_app(self.gateway, config), tokens, approvers)

    def start(self) -> None:
        import uvicorn

        app = self._app()
        tls = self.config.tls
        if tls is not None:  # uvicorn reads them by name: first as every key is read
            tls.files("control.tls")
        sock = self._socket()
        config = uvicorn.Config(app, log_level="warning", lifespan="off",
                                http=guarded_h11(self.config.header_timeout_s),
                                ssl_certfile=str(tls.cert) if tls else None,
                                ssl_keyfile=str(tls.key) if tls else None,
                                timeout_keep_alive=30,
                                limit_concurrency=self.config.max_connections)
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, kwargs={"sockets": [sock]},
                                        daemon=True, name="control-api")
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self._server.started and self._thread.is_alive() and \
                time.monotonic() < deadline:
            time.sleep(0.02)
        if not self._server.started:
            raise OSError(f"control API did not start on {self.config.listen}")
        log.info("control API on %s (%s%s)", self.address,
                 "bearer tokens" if self.config.auth else "no tokens: socket mode 0600",
                 ", approvers' tokens" if self.config.approvers else "")

    def close(self) -> None:
        if self._server is not None and self._thread is not None:
            self._server.should_exit = True
            self._thread.join(5)
        path = self.config.socket_path
        if path is not None and path.is_socket():
            path.unlink()
