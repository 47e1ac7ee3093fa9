"""The control API over HTTP: JSON on loopback TCP or a Unix socket (mode 0600), bearer
tokens, TLS; Starlette on uvicorn in a thread of its own.

    GET  /v1/products            GET /v1/products/{name}      GET /v1/look?route=R
    GET  /v1/status              GET /v1/policy
    POST /v1/detect {image, route}   /v1/infer {route, image}   /v1/ask {question}
         /v1/transcribe {audio}      /v1/say {text}
         /v1/check {target, message} /v1/publish {target, message, approved}

Images and audio travel base64. Errors: {"error": why, "kind": InvalidInput | NotReady |
Refused | Internal} with 400, 503, 403 or 500; nothing internal is told.
"""

from __future__ import annotations

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
from starlette.types import ASGIApp, Receive, Scope, Send

from oricf.errors import InvalidInput, NotReady, OricfError
from oricf.gateway.agents.policy import Refused
from oricf.gateway.control.api import Gateway, Json
from oricf.gateway.control.config import ControlConfig
from oricf.metrics import split_listen
from oricf.tls import token_matches

log = logging.getLogger(__name__)

STATUS = {"InvalidInput": 400, "Refused": 403, "NotReady": 503}


class BearerTokens:
    """ASGI middleware: every HTTP request carries `Authorization: Bearer TOKEN`."""

    def __init__(self, app: ASGIApp, tokens: tuple[bytes, ...]) -> None:
        self.app = app
        self.tokens = tokens

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            given = dict(scope.get("headers") or []).get(b"authorization", b"")
            scheme, _, token = given.decode("latin-1").partition(" ")
            if scheme.lower() != "bearer" or not token_matches(token.strip(), self.tokens):
                response = JSONResponse({"error": "missing or wrong bearer token"}, 401,
                                        headers={"WWW-Authenticate": "Bearer"})
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)


def error_kind(exc: Exception) -> str:
    for kind in (Refused, InvalidInput, NotReady):
        if isinstance(exc, kind):
            return kind.__name__
    return "InvalidInput" if isinstance(exc, OricfError) else "Internal"


def b64(data: Any, what: str) -> bytes:
    if not isinstance(data, str):
        raise InvalidInput(f"{what}: base64 text expected")
    try:
        return base64.b64decode(data, validate=True)
    except (binascii.Error, ValueError):
        raise InvalidInput(f"{what}: not valid base64") from None


def control_app(gateway: Gateway, max_body_bytes: int) -> Starlette:
    async def body(request: Request) -> Json:
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > max_body_bytes:
                raise InvalidInput(f"request body over {max_body_bytes:,} bytes")
            chunks.append(chunk)
        try:
            data = json.loads(b"".join(chunks) or b"{}")
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
                kind = error_kind(exc)
                if kind == "Internal":
                    log.exception("control API %s failed", request.url.path)
                return JSONResponse({"error": "internal error" if kind == "Internal"
                                     else str(exc), "kind": kind}, STATUS.get(kind, 500))
        return handle

    def look(request: Request, _: Json) -> Json:
        info, jpeg = gateway.look(request.query_params.get("route"))
        return {**info, "image": base64.b64encode(jpeg).decode()}

    g = gateway
    reads: dict[str, Callable[[Request, Json], Any]] = {
        "/v1/products": lambda r, d: {"products": g.products()},
        "/v1/products/{name}": lambda r, d: g.read_product(r.path_params["name"]),
        "/v1/look": look,
        "/v1/status": lambda r, d: g.status(),
        "/v1/policy": lambda r, d: g.policy(),
    }
    calls: dict[str, Callable[[Request, Json], Any]] = {
        "/v1/detect": lambda r, d: g.detect(b64(d.get("image"), "image"), d.get("route")),
        "/v1/infer": lambda r, d: g.infer(
            str(d.get("route", "")),
            None if d.get("image") is None else b64(d.get("image"), "image"),
            d.get("tensors")),
        "/v1/ask": lambda r, d: g.ask(d.get("question")),  # type: ignore[arg-type]
        "/v1/transcribe": lambda r, d: g.transcribe(b64(d.get("audio"), "audio")),
        "/v1/say": lambda r, d: g.say(d.get("text")),  # type: ignore[arg-type]
        "/v1/check": lambda r, d: g.check(str(d.get("target", "")), d.get("message")),
        "/v1/publish": lambda r, d: g.publish(str(d.get("target", "")), d.get("message"),
                                              d.get("approved") is True),
    }
    routes = [Route(path, endpoint(work)) for path, work in reads.items()]
    routes += [Route(path, endpoint(work, post=True), methods=["POST"])
               for path, work in calls.items()]
    return Starlette(routes=routes)


class ControlServer:
    """start() binds (raising if it cannot) and serves in a thread; close() stops it."""

    def __init__(self, config: ControlConfig, gateway: Gateway) -> None:
        self.config = config
        self.gateway = gateway
        self.address = ""
        self._server: Any = None
        self._thread: threading.Thread | None = None

    def _socket(self) -> socket.socket:
        path = self.config.socket_path
        if path is not None:
            if path.is_socket():
                path.unlink()  # left by a gateway that did not stop cleanly
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            old = os.umask(0o177)  # born 0600: only this user may connect
            try:
                sock.bind(str(path))
            finally:
                os.umask(old)
            self.address = f"unix:{path}"
            return sock
        host, port = split_listen(self.config.listen)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host.strip("[]"), port))
        scheme = "https" if self.config.tls else "http"
        shown = f"[{host}]" if ":" in host else host  # an IPv6 address in a URL
        self.address = f"{scheme}://{shown}:{sock.getsockname()[1]}"
        return sock

    def start(self) -> None:
        import uvicorn

        app: Any = control_app(self.gateway, self.config.max_body_bytes)
        if self.config.auth is not None:
            app = BearerTokens(app, tuple(t.encode() for t in self.config.auth.tokens()))
        tls = self.config.tls
        sock = self._socket()
        config = uvicorn.Config(app, log_level="warning", lifespan="off",
                                ssl_certfile=str(tls.cert) if tls else None,
                                ssl_keyfile=str(tls.key) if tls else None,
                                timeout_keep_alive=30, limit_concurrency=64)
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
        log.info("control API on %s (%s)", self.address,
                 "bearer tokens" if self.config.auth else "no tokens: socket mode 0600")

    def close(self) -> None:
        if self._server is not None and self._thread is not None:
            self._server.should_exit = True
            self._thread.join(5)
        path = self.config.socket_path
        if path is not None and path.is_socket():
            path.unlink()
