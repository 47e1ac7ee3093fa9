"""MCP over streamable HTTP (the SDK's Starlette app on uvicorn): loopback by default;
bearer tokens and TLS, both required for any other address (oricf.tls.check_exposure); a
cap on request bodies; the SDK's DNS-rebinding protection on loopback; a deadline for
request headers and room for a client that asks when every connection is taken
(oricf.http_connections)."""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass
from typing import Any, ClassVar

from mcp.server.mcpserver import MCPServer
from pydantic import ValidationError
from pydantic_core import ErrorDetails

from oricf.errors import ConfigError
from oricf.hosts import ListenAddress
from oricf.http_connections import guarded_h11
from oricf.tls import ListenerConfig, ListenerKeys, ServerTls
from oricf.tokens import BearerTokens

log = logging.getLogger(__name__)

PATH = "/mcp"
MAX_CONNECTIONS = 64
# A connection whose request headers are not complete this long after it opened (or after
# its last answer) is closed: no client needs long to send a few hundred bytes of headers.
HEADER_TIMEOUT_S = 10.0


class McpListener(ListenerConfig):
    """MCP's listener, given as flags (oricf.tls.check_exposure names them)."""

    listen: ListenAddress
    keys: ClassVar[ListenerKeys] = ListenerKeys(
        listen="--listen", tls="--tls-cert/--tls-key", auth="--auth-token-file")

    @classmethod
    def from_flags(cls, args: argparse.Namespace) -> McpListener:
        try:
            return cls.model_validate({
                "listen": args.listen,
                "tls": {"cert": args.tls_cert, "key": args.tls_key} if args.tls_cert else None,
                "auth": {"file": args.auth_token_file} if args.auth_token_file else None})
        except ValidationError as exc:
            raise ConfigError("\n".join(cls._flag_message(e) for e in exc.errors())) from None

    @classmethod
    def _flag_message(cls, error: ErrorDetails) -> str:
        """A schema error as the command line says it (`--listen: ...`); the exposure rule's
        own message names its flags already."""
        message = str(error["msg"]).removeprefix("Value error, ")
        if not error["loc"]:
            return message
        flags = {"listen": cls.keys.listen, "tls": cls.keys.tls, "auth": cls.keys.auth}
        return f"{flags.get(str(error['loc'][0]), error['loc'][0])}: {message}"


@dataclass(frozen=True)
class HttpSettings:
    host: str
    port: int
    tokens: tuple[bytes, ...]
    tls: ServerTls | None
    max_request_bytes: int

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> HttpSettings:
        if (args.tls_cert is None) != (args.tls_key is None):
            raise ConfigError("--tls-cert and --tls-key go together")
        listener = McpListener.from_flags(args)
        try:
            tokens = (tuple(t.encode() for t in listener.auth.tokens())
                      if listener.auth else ())
        except ConfigError as exc:
            raise ConfigError(f"{McpListener.keys.auth}: {exc}") from None
        if listener.tls is not None:  # uvicorn reads them by name: first as every key is
            try:                      # read, so a FIFO or a device is refused, not waited on
                listener.tls.files()
            except ConfigError as exc:
                raise ConfigError(f"{McpListener.keys.tls}: {exc}") from None
        if not 1024 <= args.max_request_bytes <= 256 * 1024 * 1024:
            raise ConfigError("--max-request-bytes: from 1024 to 268435456")
        return cls(listener.listen.host, listener.listen.port, tokens, listener.tls,
                   args.max_request_bytes)


def http_app(app: MCPServer, settings: HttpSettings) -> Any:
    asgi: Any = app.streamable_http_app(streamable_http_path=PATH, host=settings.host,
                                        max_request_body_size=settings.max_request_bytes)
    return BearerTokens(asgi, settings.tokens) if settings.tokens else asgi


def serve_http(app: MCPServer, settings: HttpSettings) -> None:
    import uvicorn

    tls = settings.tls
    config = uvicorn.Config(
        http_app(app, settings), host=settings.host, port=settings.port, log_level="warning",
        ssl_certfile=str(tls.cert) if tls else None, ssl_keyfile=str(tls.key) if tls else None,
        lifespan="on", timeout_keep_alive=30, limit_concurrency=MAX_CONNECTIONS,
        http=guarded_h11(HEADER_TIMEOUT_S))
    scheme = "https" if tls else "http"
    log.info("MCP on %s://%s:%d%s (%s)", scheme, settings.host, settings.port, PATH,
             "bearer tokens" if settings.tokens else "no tokens: this machine only")
    uvicorn.Server(config).run()
