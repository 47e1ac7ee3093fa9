"""Certificates for TLS tests on this machine: a CA, a server certificate for localhost and
127.0.0.1, a client certificate, and (if given) a token file whose last token is `token`."""

from __future__ import annotations

from pathlib import Path

import pytest

from oricf.launch.certs import make_certificates


def local_certificates(factory: pytest.TempPathFactory, token: str | None = None) -> Path:
    folder = factory.mktemp("certs")
    make_certificates(folder, ["localhost", "127.0.0.1"])
    if token is not None:
        (folder / "tokens").write_text(f"another-token\n{token}\n")
    return folder
