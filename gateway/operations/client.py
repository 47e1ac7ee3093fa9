"""The control API from another process (`oricf mcp --attach`): api.Operations over HTTP, on a
Unix socket or http(s)://HOST:PORT, with a bearer token; the server's errors come back as
the same exception types (InvalidInput, NotReady, Refused).

Names a caller passes are checked here by the rule the gateway applies (operations.names)
before they reach a URL, and every path segment is percent-escaped: `../status` or
`people_count?x=1` is no data product, never another endpoint or a query.
"""

from __future__ import annotations

import base64
import ssl
from pathlib import Path
from typing import Any
from urllib.parse import quote

import httpx

from oricf.errors import ConfigError, InvalidInput, NotReady, OricfError
from oricf.gateway.actuation.policy import Refused
from oricf.gateway.operations.api import PATHS, Json
from oricf.gateway.operations.names import known_product
from oricf.tls import TokenSource
from oricf.yamlfile import read_limited

ERRORS: dict[str, type[OricfError]] = {"InvalidInput": InvalidInput, "NotReady": NotReady,
                                       "Refused": Refused}
TIMEOUT_S = 60.0  # a language model's answer may take this long on a small CPU


def path_segment(name: str) -> str:
    """`name` as one path segment: every reserved character escaped ('/', '?', '#', '%'),
    and the dots of a '.' or '..' segment too, which a URL would otherwise resolve."""
    escaped = quote(name, safe="")
    return escaped.replace(".", "%2E") if escaped in (".", "..") else escaped


def ca_context(ca: Path) -> ssl.SSLContext:
    """A client context trusting the CA of --ca, read as every certificate is (a regular
    file within a size cap: a FIFO or a device is refused rather than waited on)."""
    try:
        pem = read_limited(ca, "a certificate").decode("latin-1")
        return ssl.create_default_context(cadata=pem)
    except ConfigError as exc:
        raise ConfigError(f"--ca: {exc}") from None
    except ssl.SSLError as exc:
        raise ConfigError(f"--ca: {ca}: not a PEM certificate: {exc.reason}") from None


class ControlClient:
    def __init__(self, address: str, token_file: Path | None = None,
                 ca: Path | None = None) -> None:
        headers = {}
        if token_file is not None:
            try:
                token = TokenSource(file=token_file).tokens()[0]
            except ConfigError as exc:
                raise ConfigError(f"--token-file: {exc}") from None
            headers["Authorization"] = f"Bearer {token}"
        if address.startswith("unix:"):
            transport = httpx.HTTPTransport(uds=address[len("unix:"):])
            self._http = httpx.Client(transport=transport, base_url="http://gateway",
                                      headers=headers, timeout=TIMEOUT_S)
        elif address.startswith(("http://", "https://")):
            verify: ssl.SSLContext | bool = ca_context(ca) if ca is not None else True
            self._http = httpx.Client(base_url=address.rstrip("/"), headers=headers,
                                      timeout=TIMEOUT_S, verify=verify)
        else:
            raise ConfigError(f"--attach {address}: give unix:PATH or http(s)://HOST:PORT")
        self.address = address

    def _call(self, operation: str, path: dict[str, str] | None = None, **kwargs: Any
              ) -> Any:
        """The operation at its path in PATHS, `path` filling the path's parameters; kwargs
        are httpx's (json, params)."""
        api = PATHS[operation]
        try:
            response = self._http.request(api.http, api.url(**(path or {})), **kwargs)
        except httpx.HTTPError as exc:
            raise NotReady(f"gateway control API at {self.address}: {exc}") from None
        try:
            data = response.json()
        except ValueError:
            raise NotReady(f"gateway control API: HTTP {response.status_code}") from None
        if response.status_code == 401:
            raise NotReady("gateway control API: missing or wrong bearer token")
        if response.status_code >= 400:
            error = ERRORS.get(str(data.get("kind")), NotReady)
            raise error(str(data.get("error", "failed")))
        return data

    def products(self) -> list[Json]:
        return list(self._call("products")["products"])

    def read_product(self, name: str) -> Json:
        known_product(name, (p["name"] for p in self.products()))
        return dict(self._call("read_product", path={"name": path_segment(name)}))

    def look(self, route: str | None = None) -> tuple[Json, bytes]:
        data = self._call("look", params={"route": route} if route else None)
        return data, base64.b64decode(data.pop("image"))

    def detect(self, image: bytes, route: str | None = None) -> Json:
        return dict(self._call("detect", json={
            "image": base64.b64encode(image).decode(), "route": route}))

    def infer(self, route: str, image: bytes | None = None,
              tensors: dict[str, Any] | None = None) -> Json:
        body: Json = {"route": route, "tensors": tensors}
        if image is not None:
            body["image"] = base64.b64encode(image).decode()
        return dict(self._call("infer", json=body))

    def ask(self, question: str) -> Json:
        return dict(self._call("ask", json={"question": question}))

    def transcribe(self, audio: bytes) -> Json:
        return dict(self._call("transcribe",
                               json={"audio": base64.b64encode(audio).decode()}))

    def say(self, text: str) -> Json:
        return dict(self._call("say", json={"text": text}))

    def status(self) -> Json:
        return dict(self._call("status"))

    def policy(self) -> Json:
        return dict(self._call("policy"))

    def check(self, target: str, message: Json) -> Json:
        return dict(self._call("check", json={"target": target,
                                                          "message": message}))

    def publish(self, target: str, message: Json, approved: bool = False) -> Json:
        return dict(self._call("publish", json={
            "target": target, "message": message, "approved": approved}))

    def close(self) -> None:
        self._http.close()
