"""Bearer tokens in front of an ASGI app: the gateway's control API and MCP over streamable
HTTP take the same middleware, each from here, so neither surface imports the other."""

from __future__ import annotations

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from oricf.tls import token_matches

APPROVER = "oricf.approver"  # in a request's scope: it carries a token of `approvers`


def bearer(scope: Scope) -> str | None:
    """The request's bearer token, if it gives one."""
    given = dict(scope.get("headers") or []).get(b"authorization")
    if given is None:
        return None
    scheme, _, token = given.decode("latin-1").partition(" ")
    return token.strip() if scheme.lower() == "bearer" else None


async def unauthorized(scope: Scope, receive: Receive, send: Send) -> None:
    response = JSONResponse({"error": "missing or wrong bearer token"}, 401,
                            headers={"WWW-Authenticate": "Bearer"})
    await response(scope, receive, send)


class BearerTokens:
    """ASGI middleware: with `tokens`, every HTTP request carries `Authorization: Bearer
    TOKEN` with one of them or of `approvers`; a token of `approvers` also marks the request
    as an approver's (scope[APPROVER]): of the control API's clients, the one whose
    `approved: true` is taken."""

    def __init__(self, app: ASGIApp, tokens: tuple[bytes, ...],
                 approvers: tuple[bytes, ...] = ()) -> None:
        self.app = app
        self.tokens = tokens
        self.approvers = approvers

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            token = bearer(scope)
            approver = token is not None and bool(self.approvers) and \
                token_matches(token, self.approvers)
            if self.tokens and not approver and \
                    (token is None or not token_matches(token, self.tokens)):
                await unauthorized(scope, receive, send)
                return
            scope[APPROVER] = approver
        await self.app(scope, receive, send)
