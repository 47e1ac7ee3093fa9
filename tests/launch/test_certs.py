"""`oricf certs` writes new private files, never through a link, and keeps a CA unless told."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from oricf.errors import ConfigError
from oricf.launch.certs import make_certificates

PRIVATE = ("ca.key", "server.key", "client.key", "tokens")


def mode(path: Path) -> int:
    return stat.S_IMODE(path.lstat().st_mode)


def certs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "oricf", "certs", *args],
                          capture_output=True, text=True, timeout=60)


def test_keys_and_token_are_private_even_over_world_readable_files(tmp_path: Path) -> None:
    for name in ("server.key", "client.key"):
        (tmp_path / name).write_text("old")
        os.chmod(tmp_path / name, 0o644)
    make_certificates(tmp_path, ["localhost"])
    assert {name: mode(tmp_path / name) for name in PRIVATE} == dict.fromkeys(PRIVATE, 0o600)
    assert mode(tmp_path / "server.pem") == 0o644
    assert (tmp_path / "server.key").read_text().startswith("-----BEGIN PRIVATE KEY-----")


def test_a_link_at_a_key_is_replaced_not_written_through(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere"
    target.write_text("not a key\n")
    folder = tmp_path / "certs"
    folder.mkdir()
    (folder / "server.key").symlink_to(target)
    make_certificates(folder, ["localhost"])
    assert target.read_text() == "not a key\n"
    assert not (folder / "server.key").is_symlink() and mode(folder / "server.key") == 0o600


def test_a_linked_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    with pytest.raises(ConfigError, match="is a symbolic link"):
        make_certificates(tmp_path / "link", ["localhost"])
    assert list((tmp_path / "real").iterdir()) == []


def test_an_existing_ca_is_kept_unless_forced(tmp_path: Path) -> None:
    assert certs(str(tmp_path)).returncode == 0
    ca = (tmp_path / "ca.pem").read_bytes()
    token = (tmp_path / "tokens").read_text()
    refused = certs(str(tmp_path))
    assert refused.returncode == 2 and "holds a CA already" in refused.stderr
    assert "--force" in refused.stderr and (tmp_path / "ca.pem").read_bytes() == ca
    assert certs(str(tmp_path), "--force").returncode == 0
    assert (tmp_path / "ca.pem").read_bytes() != ca
    assert (tmp_path / "tokens").read_text() == token  # a token handed out stays valid
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftovers
