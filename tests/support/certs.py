"""Certificates for TLS tests on this machine: a CA, a server certificate for localhost and
127.0.0.1, a client certificate, and (if given) a token file whose last token is `token`.

`certs` is the session's set (registered in tests/conftest.py), made once: its token file's
last token is TOKEN. Tests only read it; a test that needs certificates of its own (another
CA, other names) makes them in its tmp_path with make_certificates."""

from __future__ import annotations

from pathlib import Path

import pytest

from oricf.launch.certs import make_certificates

TOKEN = "s3cret-token-for-the-tests"


def local_certificates(factory: pytest.TempPathFactory, token: str | None = None) -> Path:
    folder = factory.mktemp("certs")
    make_certificates(folder, ["localhost", "127.0.0.1"])
    if token is not None:
        (folder / "tokens").write_text(f"another-token\n{token}\n")
    return folder


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The session's certificates and token file (TOKEN), read by every TLS test."""
    return local_certificates(tmp_path_factory, TOKEN)
