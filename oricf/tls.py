"""Transport security shared by the services, the gateway and the health probe: the YAML
schemas for TLS and tokens, and gRPC credentials and Python SSL contexts from them. A
deployment's own certificates come from `oricf certs` (oricf.launch.certs)."""

from __future__ import annotations

import hmac
import os
import ssl
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import ClassVar

import grpc
from pydantic import Field, model_validator

from oricf.config import FilePath, Schema
from oricf.errors import ConfigError
from oricf.hosts import Address, ListenTarget, UnixSocket


def _read(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{what}: cannot read {path}: {exc.strerror}") from None


class ServerTls(Schema):
    """A service's certificate; with client_ca, callers must present a certificate it signed."""

    cert: FilePath
    key: FilePath
    client_ca: FilePath | None = Field(None, description="require client certificates (mTLS)")

    def credentials(self) -> grpc.ServerCredentials:
        client_ca = _read(self.client_ca, "tls.client_ca") if self.client_ca else None
        return grpc.ssl_server_credentials(
            [(_read(self.key, "tls.key"), _read(self.cert, "tls.cert"))],
            root_certificates=client_ca, require_client_auth=client_ca is not None)

    def ssl_context(self, what: str) -> ssl.SSLContext:
        """The same certificate (and client CA) for a server that speaks TLS through Python's
        ssl module (HTTP); `what` names the YAML key in errors."""
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        try:
            context.load_cert_chain(self.cert, self.key)
            if self.client_ca is not None:
                context.load_verify_locations(self.client_ca)
                context.verify_mode = ssl.CERT_REQUIRED
        except (OSError, ssl.SSLError) as exc:
            raise ConfigError(f"{what}: cannot load {self.cert}, {self.key} or "
                              f"{self.client_ca}: {exc}") from None
        return context


class ClientTls(Schema):
    """How a caller checks the service (ca) and, for mTLS, proves who it is (cert, key)."""

    ca: FilePath = Field(description="the CA that signed the service's certificate")
    cert: FilePath | None = None
    key: FilePath | None = None
    server_name: str | None = Field(
        None, description="the name in the service's certificate, if not the address's host")

    @model_validator(mode="after")
    def _pair(self) -> ClientTls:
        if (self.cert is None) != (self.key is None):
            raise ValueError("give both cert and key, or neither")
        return self

    def channel(self, address: str, options: list[tuple[str, object]]) -> grpc.Channel:
        credentials = grpc.ssl_channel_credentials(
            root_certificates=_read(self.ca, "tls.ca"),
            private_key=_read(self.key, "tls.key") if self.key else None,
            certificate_chain=_read(self.cert, "tls.cert") if self.cert else None)
        if self.server_name:
            options = [*options, ("grpc.ssl_target_name_override", self.server_name)]
        return grpc.secure_channel(address, credentials, options=options)


class TokenSource(Schema):
    """Bearer tokens, one per line in a file, or in an environment variable."""

    file: FilePath | None = None
    env: str | None = None

    @model_validator(mode="after")
    def _one(self) -> TokenSource:
        if (self.file is None) == (self.env is None):
            raise ValueError("give exactly one of file or env")
        return self

    def tokens(self) -> list[str]:
        if self.file is not None:
            text = _read(self.file, "token file").decode("utf-8", "replace")
            where = str(self.file)
        else:
            assert self.env is not None
            text = os.environ.get(self.env, "")
            where = f"${self.env}"
        tokens = [line.strip() for line in text.splitlines() if line.strip()]
        if not tokens:
            raise ConfigError(f"no token in {where}")
        return tokens


def token_matches(given: str, tokens: Sequence[bytes]) -> bool:
    """Whether `given` is one of `tokens`. Every token is compared in constant time, so the
    time taken says nothing about which one was close."""
    given_bytes = given.encode()
    matches = [hmac.compare_digest(given_bytes, known) for known in tokens]
    return any(matches)


def open_channel(address: str, tls: ClientTls | None,
                 options: Sequence[tuple[str, object]] = ()) -> grpc.Channel:
    if tls is None:
        return grpc.insecure_channel(address, options=list(options))
    return tls.channel(address, list(options))


class Exposure(Enum):
    """What a listener asks of a client beyond the address it listens on."""

    # Beyond loopback, TLS and bearer tokens; on loopback, whatever is configured.
    SECURED = "secured"
    # As SECURED, and bearer tokens on every TCP address, loopback included: any local user
    # could otherwise use it (the control API drives the robot's agent targets).
    TOKENS_ON_TCP = "tokens on tcp"
    # Any address, TLS optional: what it serves is no secret (metrics are counts, scraped
    # across the network by compose and Kubernetes).
    OPEN = "open"


@dataclass(frozen=True)
class ListenerKeys:
    """How a listener's settings are named where the user gives them (YAML keys or flags)."""

    listen: str = "listen"
    tls: str = "tls"
    auth: str = "auth"


def check_exposure(listen: Address | UnixSocket, *, tls: bool, tokens: bool,
                   exposure: Exposure, keys: ListenerKeys = ListenerKeys()) -> None:
    """The one rule for every listener: whatever is reachable from other machines needs TLS
    and bearer tokens. A Unix socket and a loopback address are this machine only.
    ValueError naming the keys to set otherwise."""
    if exposure is Exposure.OPEN or isinstance(listen, UnixSocket):
        return
    if not listen.is_loopback and not (tls and tokens):
        raise ValueError(f"{keys.listen} {listen} is reachable from other machines: it needs "
                         f"{keys.auth} and {keys.tls}; set both {keys.tls} and {keys.auth}, "
                         f"or listen on 127.0.0.1")
    if exposure is Exposure.TOKENS_ON_TCP and not tokens:
        raise ValueError(f"{keys.listen} {listen}: a TCP address needs {keys.auth} (bearer "
                         f"tokens): any local user could otherwise use it")


class Listener(Schema):
    """Where a server listens and its TLS, checked against its exposure (check_exposure).
    A subclass narrows `listen` (most take host:port only) and gives its default."""

    listen: ListenTarget
    tls: ServerTls | None = Field(None, description="serve TLS (client certificates required "
                                                    "with client_ca)")
    exposure: ClassVar[Exposure] = Exposure.SECURED
    keys: ClassVar[ListenerKeys] = ListenerKeys()

    @property
    def token_source(self) -> TokenSource | None:
        return None

    @model_validator(mode="after")
    def _exposure(self) -> Listener:
        check_exposure(self.listen, tls=self.tls is not None,
                       tokens=self.token_source is not None, exposure=self.exposure,
                       keys=self.keys)
        return self


class ListenerConfig(Listener):
    """A listener with bearer tokens: the live view, the control API, MCP over HTTP, and
    the text channels."""

    auth: TokenSource | None = Field(None, description="bearer tokens")

    @property
    def token_source(self) -> TokenSource | None:
        return self.auth
