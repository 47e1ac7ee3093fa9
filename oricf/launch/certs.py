"""`oricf certs`: a local CA, service and client certificates, and a token for a deployment.

    oricf certs DIR --host edge.local --host 127.0.0.1 [--force]

writes DIR/ca.pem (the deployment's CA; its key ca.key stays with whoever issues
certificates), server.pem/server.key (for the services; the hosts as subject alternative
names), client.pem/client.key (for gateways, when services require client certificates) and
DIR/tokens, one random bearer token for `server.auth` and the gateway's `token`.

Every file is written new: to a temporary file in DIR, created readable by its owner only
for keys and the token, then renamed over the name, so an existing file's looser mode is
never kept and a link at that name is replaced, not followed. A folder that already holds a
CA is refused without --force: a new CA would invalidate every certificate it signed.
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import os
import secrets
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from oricf.errors import ConfigError
from oricf.files import write_atomically

if TYPE_CHECKING:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric.ec import EllipticCurvePrivateKey

VALID_DAYS = 825  # the longest validity clients accept for a server certificate
CA_FILES = ("ca.pem", "ca.key")


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


def write_file(path: Path, data: bytes, private: bool = False) -> None:
    """A new file at path (0600 if private, else 0644): written beside it, then renamed
    (a link at path is replaced, never written through)."""
    write_atomically(path, data, 0o600 if private else 0o644)


def _key_bytes(key: EllipticCurvePrivateKey) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _check_folder(folder: Path, force: bool) -> None:
    if folder.is_symlink():
        raise ConfigError(f"{folder}: is a symbolic link; give the real folder")
    folder.mkdir(parents=True, exist_ok=True)
    existing = [name for name in CA_FILES if os.path.lexists(folder / name)]
    if existing and not force:
        raise ConfigError(f"{folder}: holds a CA already ({', '.join(existing)}); a new one "
                          f"invalidates every certificate it signed. Use --force to replace "
                          f"it")


def make_certificates(folder: Path, hosts: list[str], force: bool = False) -> None:
    """A CA, a server certificate for hosts, and a client certificate, into folder."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    _check_folder(folder, force)
    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = _name("ORICF deployment CA")
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now).not_valid_after(now + datetime.timedelta(days=3650))
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .sign(ca_key, hashes.SHA256()))
    write_file(folder / "ca.key", _key_bytes(ca_key), private=True)
    write_file(folder / "ca.pem", ca.public_bytes(serialization.Encoding.PEM))
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
        write_file(folder / f"{role}.key", _key_bytes(key), private=True)
        write_file(folder / f"{role}.pem", cert.public_bytes(serialization.Encoding.PEM))
    tokens = folder / "tokens"
    if not tokens.exists() or tokens.is_symlink():  # a token already handed out stays valid
        write_file(tokens, (secrets.token_urlsafe(32) + "\n").encode(), private=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf certs", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path)
    parser.add_argument("--host", action="append", default=[],
                        help="a name or address the services are reached by (repeatable; "
                             "default localhost and 127.0.0.1)")
    parser.add_argument("--force", action="store_true",
                        help="replace a CA already in the folder (every certificate it "
                             "signed stops being accepted)")
    args = parser.parse_args(argv)
    hosts = args.host or ["localhost", "127.0.0.1"]
    try:
        make_certificates(args.folder, hosts, args.force)
    except ConfigError as exc:
        print(f"oricf certs: {exc}", file=sys.stderr)
        return 2
    print(f"{args.folder}: ca.pem, server.pem/.key ({', '.join(hosts)}), client.pem/.key, "
          f"tokens")
    return 0
