"""Writing a file or a folder so that a reader never sees half of it and two writers never
collide.

Each writer writes under a temporary name of its own, made by `tempfile` beside the target
(so the rename stays on one file system), then renames it into place with `os.replace`,
which is atomic. Two processes making the same cache file at once (two services converting
the same weights into a fresh store) each write their own copy, and the last rename wins
with the same content; a fixed temporary name would let one process rename or remove the
file the other is still writing.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

log = logging.getLogger(__name__)


@contextlib.contextmanager
def atomic_file(path: Path, mode: int = 0o644) -> Iterator[BinaryIO]:
    """A binary file to write, put at `path` (with permissions `mode`) once the block ends;
    removed, and `path` left as it was, if the block raises. A link at `path` is replaced,
    never written through."""
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as out:
            yield out
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def write_atomically(path: Path, data: bytes, mode: int = 0o644) -> None:
    """`data` at `path`, written whole under a temporary name of this writer's and renamed."""
    with atomic_file(path, mode) as out:
        out.write(data)


@contextlib.contextmanager
def staged_folder(folder: Path) -> Iterator[Path]:
    """A temporary folder beside `folder`, moved into its place whole once the block has
    written it, and removed if the block fails. Where another writer has put the folder in
    place meanwhile, theirs is kept and this one dropped: both were made from the same
    inputs, and a folder in use is never replaced under its reader."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    staged = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        yield staged
        try:
            os.replace(staged, folder)
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST) or not folder.is_dir():
                raise
            log.info("%s: already made by another writer; that one is kept", folder)
    finally:
        shutil.rmtree(staged, ignore_errors=True)
