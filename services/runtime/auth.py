"""Bearer-token authentication for a service: `authorization: Bearer <token>` metadata,
compared in constant time with the configured tokens, before any handler runs.

No token: UNAUTHENTICATED. A token that is not one of them: PERMISSION_DENIED. Health checks
are exempt, so orchestrators' probes (which carry no credentials) still see the service; a
health answer reveals only SERVING or not. Tokens are never logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import grpc

from oricf.tls import token_matches

log = logging.getLogger(__name__)

EXEMPT_PREFIX = "/grpc.health.v1."


def _bearer(metadata: Sequence[tuple[str, Any]] | None) -> str | None:
    for key, value in metadata or ():
        if key == "authorization" and isinstance(value, str):
            scheme, _, token = value.partition(" ")
            return token.strip() if scheme.lower() == "bearer" else ""
    return None


def _refusal(code: grpc.StatusCode, message: str) -> Callable[..., Any]:
    def refuse(request: Any, context: grpc.ServicerContext) -> Any:
        context.abort(code, message)

    return refuse


class TokenAuthInterceptor(grpc.ServerInterceptor):
    def __init__(self, tokens: Sequence[str]) -> None:
        self._tokens = [token.encode() for token in tokens]

    def _allowed(self, token: str) -> bool:
        return token_matches(token, self._tokens)

    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        handler = continuation(details)
        if handler is None or details.method.startswith(EXEMPT_PREFIX):
            return handler
        token = _bearer(details.invocation_metadata)
        if token is None:
            code, message = grpc.StatusCode.UNAUTHENTICATED, "authorization: Bearer TOKEN needed"
        elif not self._allowed(token):
            code, message = grpc.StatusCode.PERMISSION_DENIED, "the token is not accepted"
        else:
            return handler
        log.debug("%s refused: %s", details.method, code.name)
        refuse = _refusal(code, message)
        kinds = ("unary_unary", "unary_stream", "stream_unary", "stream_stream")
        kind = next(k for k in kinds if getattr(handler, k) is not None)
        return handler._replace(**{kind: refuse})
