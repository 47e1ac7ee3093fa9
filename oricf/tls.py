"""Transport security shared by the services, the gateway and the health probe: the YAML
schemas for TLS and tokens, gRPC credentials from them, and a local CA for a deployment.

    oricf certs DIR --host edge.local --host 127.0.0.1

writes DIR/ca.pem (the deployment's CA; its key ca.key stays with whoever issues
certificates), server.pem/server.key (for the services; the hosts as subject alternative
names), client.pem/client.key (for gateways, when services require client certificates) and
DIR/tokens, one random bearer token for `server.auth` and the gateway's `token`. Keys and
the token are written readable by their owner only. Certificates use the `cryptography` library.
"""

from __future__ import annotations

import argparse
import datetime
import hmac
import ipaddress
import os
import secrets
import ssl
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import grpc
from pydantic import Field, model_validator

from oricf.config import FilePath, Schema
from oricf.errors import ConfigError

if TYPE_CHECKING:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric.ec import EllipticCurvePrivateKey

VALID_DAYS = 825  # the longest validity clients accept for a server certificate


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


def _name(common_name: str) -> x509.Name:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _san(hosts: list[str]) -> x509.SubjectAlternativeName:
    from cryptography import x509

    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def _write_private(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)


def _write_key(path: Path, key: EllipticCurvePrivateKey) -> None:
    from cryptography.hazmat.primitives import serialization

    _write_private(path, key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))


def make_certificates(folder: Path, hosts: list[str]) -> None:
    """A CA, a server certificate for hosts, and a client certificate, into folder."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = _name("ORICF deployment CA")
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now).not_valid_after(now + datetime.timedelta(days=3650))
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .sign(ca_key, hashes.SHA256()))
    _write_key(folder / "ca.key", ca_key)
    (folder / "ca.pem").write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    for role, usage in (("server", x509.ExtendedKeyUsageOID.SERVER_AUTH),
                        ("client", x509.ExtendedKeyUsageOID.CLIENT_AUTH)):
        key = ec.generate_private_key(ec.SECP256R1())
        builder = (x509.CertificateBuilder().subject_name(_name(f"oricf-{role}"))
                   .issuer_name(ca_name).public_key(key.public_key())
                   .serial_number(x509.random_serial_number()).not_valid_before(now)
                   .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
                   .add_extension(x509.BasicConstraints(ca=False, path_length=None),
                                  critical=True)
                   .add_extension(x509.ExtendedKeyUsage([usage]), critical=False))
        if role == "server":
            builder = builder.add_extension(_san(hosts), critical=False)
        cert = builder.sign(ca_key, hashes.SHA256())
        _write_key(folder / f"{role}.key", key)
        (folder / f"{role}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    if not (folder / "tokens").exists():  # a token already handed out stays valid
        _write_private(folder / "tokens", (secrets.token_urlsafe(32) + "\n").encode())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf certs", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path)
    parser.add_argument("--host", action="append", default=[],
                        help="a name or address the services are reached by (repeatable; "
                             "default localhost and 127.0.0.1)")
    args = parser.parse_args(argv)
    hosts = args.host or ["localhost", "127.0.0.1"]
    make_certificates(args.folder, hosts)
    print(f"{args.folder}: ca.pem, server.pem/.key ({', '.join(hosts)}), client.pem/.key, "
          f"tokens")
    return 0
