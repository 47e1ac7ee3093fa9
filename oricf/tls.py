"""Transport security shared by the services, the gateway and the health probe: the YAML
schemas for TLS and tokens, and gRPC credentials and Python SSL contexts from them. A
deployment's own certificates come from `oricf certs` (oricf.launch.certs).

Certificates, keys and token files are read as configs are (oricf.yamlfile.read_limited:
regular files only, within a size cap), so a token file that is /dev/zero or a FIFO is
refused at once rather than read for ever. A secret (a token file, a private key) that
others may write is refused, since whoever writes it chooses the token; one that every user
may read is logged as a warning. Tokens are visible ASCII, what gRPC metadata and HTTP
headers carry; a file or variable that gives none, or a token with another character, is
refused naming the file or variable and never quoting the token.
"""

from __future__ import annotations

import hmac
import logging
import os
import ssl
import stat
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, ClassVar

import grpc
from pydantic import BaseModel, Field, model_validator

from oricf.config import FilePath, Schema, format_location
from oricf.errors import ConfigError
from oricf.hosts import Address, ListenTarget, UnixSocket
from oricf.yamlfile import read_limited

log = logging.getLogger(__name__)

VISIBLE_ASCII = range(0x21, 0x7F)  # what a token may hold: gRPC metadata, HTTP headers
_warned: set[str] = set()  # secrets already said to be readable by every user


def _read(path: Path, what: str) -> bytes:
    """A certificate named by the key `what`."""
    try:
        return read_limited(path, "a certificate")
    except ConfigError as exc:
        raise ConfigError(f"{what}: {exc}") from None


def _read_secret(path: Path, what: str) -> bytes:
    """A private key named by the key `what`."""
    try:
        return read_secret(path, "a private key")
    except ConfigError as exc:
        raise ConfigError(f"{what}: {exc}") from None


def read_secret(path: Path, kind: str) -> bytes:
    """A secret's bytes (a token file, a private key), read as a config is, and refused if
    users other than its owner may write it; ConfigError naming the file otherwise."""
    def private(info: os.stat_result) -> None:
        mode = stat.S_IMODE(info.st_mode)
        if mode & 0o022:
            who = "other users" if mode & 0o002 else "its group"
            raise ConfigError(f"{path}: writable by {who} (mode {mode:04o}): whoever writes "
                              f"it chooses the secret; chmod go-w {path}")
        if mode & 0o004 and str(path) not in _warned:
            _warned.add(str(path))
            log.warning("%s: readable by every user of this machine (mode %04o); "
                        "chmod o-r %s", path, mode, path)

    return read_limited(path, kind, check=private)


def parse_tokens(data: bytes, where: str) -> list[str]:
    """The tokens of `data`, one a line, blank lines and the blanks around each skipped;
    ConfigError naming `where` (and the line, not the token) when there is none or one
    holds anything but visible ASCII."""
    tokens = []
    for number, line in enumerate(data.splitlines(), 1):
        token = line.strip()
        wrong = next((at for at, byte in enumerate(token) if byte not in VISIBLE_ASCII), None)
        if wrong is not None:
            raise ConfigError(f"{where}: line {number}, character {wrong + 1}: a token is "
                              f"visible ASCII only ('!' to '~': no space, control "
                              f"character or other letter), as gRPC metadata and HTTP "
                              f"headers carry it")
        if token:
            tokens.append(token.decode("ascii"))
    if not tokens:
        raise ConfigError(f"{where}: no token (one a line)")
    return tokens


class ServerTls(Schema):
    """A service's certificate; with client_ca, callers must present a certificate it signed."""

    cert: FilePath
    key: FilePath
    client_ca: FilePath | None = Field(None, description="require client certificates (mTLS)")

    def files(self, what: str = "tls") -> tuple[bytes, bytes, bytes | None]:
        """The key, the certificate and the client CA, read; `what` names the YAML key."""
        client_ca = _read(self.client_ca, f"{what}.client_ca") if self.client_ca else None
        return (_read_secret(self.key, f"{what}.key"), _read(self.cert, f"{what}.cert"),
                client_ca)

    def credentials(self) -> grpc.ServerCredentials:
        key, cert, client_ca = self.files()
        return grpc.ssl_server_credentials(
            [(key, cert)], root_certificates=client_ca, require_client_auth=client_ca is not None)

    def ssl_context(self, what: str) -> ssl.SSLContext:
        """The same certificate (and client CA) for a server that speaks TLS through Python's
        ssl module (HTTP); `what` names the YAML key in errors."""
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        # The ssl module reads the files by name: each is read first as credentials()
        # reads it, so a FIFO or a device is refused rather than waited on.
        self.files(what)
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

    def files(self, what: str = "tls") -> tuple[bytes, bytes | None, bytes | None]:
        """The CA, the key and the certificate (None without mTLS), read; `what` names the
        YAML key."""
        return (_read(self.ca, f"{what}.ca"),
                _read_secret(self.key, f"{what}.key") if self.key else None,
                _read(self.cert, f"{what}.cert") if self.cert else None)

    def channel(self, address: str, options: list[tuple[str, object]]) -> grpc.Channel:
        ca, key, cert = self.files()
        credentials = grpc.ssl_channel_credentials(
            root_certificates=ca, private_key=key, certificate_chain=cert)
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
        """The tokens; ConfigError naming the file or the variable (parse_tokens)."""
        if self.file is not None:
            return parse_tokens(read_secret(self.file, "a token file"), str(self.file))
        assert self.env is not None
        value = os.environ.get(self.env)
        if value is None:
            raise ConfigError(f"${self.env}: not set")
        return parse_tokens(value.encode("utf-8", "surrogateescape"), f"${self.env}")


def check_token_sources(config: BaseModel, source: str) -> None:
    """Reads every token source of a validated config, so that a token that cannot be used
    stops `--check` and the start at once, naming `source` and the key (`x.yaml:
    server.auth.file: ...`); the schema alone does not read them: a config is also checked
    where its secrets are not (planning a deployment, on another machine)."""
    for location, tokens in _token_sources(config, ()):
        key = format_location((*location, "env" if tokens.file is None else "file"))
        try:
            tokens.tokens()
        except ConfigError as exc:
            raise ConfigError(f"{source}: {key}: {exc}") from None


def _token_sources(value: Any, location: tuple[Any, ...]
                   ) -> Iterator[tuple[tuple[Any, ...], TokenSource]]:
    if isinstance(value, TokenSource):
        yield location, value
    elif isinstance(value, BaseModel):
        for name in type(value).model_fields:
            yield from _token_sources(getattr(value, name), (*location, name))
    elif isinstance(value, Mapping):
        for key, item in value.items():
            yield from _token_sources(item, (*location, key))
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            yield from _token_sources(item, (*location, index))


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
