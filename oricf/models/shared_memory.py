"""System shared memory as the Open Inference Protocol's extension uses it (Triton's), for
servers and clients on one host.

A client creates a POSIX shared-memory object (a file in /dev/shm named by its key), and
registers a region of it with the server under a name. A tensor then says where its bytes
are with three parameters instead of carrying them:

    shared_memory_region       the registered name
    shared_memory_offset       from the region's start (0 if absent)
    shared_memory_byte_size    how many bytes

Keys are plain names (letters, digits, '_', '-', '.', one leading '/'), so a key can name
nothing outside /dev/shm. ORICF's own client (`OwnedRegion`) removes an object's name as
soon as the server holds it open: the memory lives while either side keeps it open, and
nothing is left in /dev/shm when either side dies, even by SIGKILL.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from oricf.errors import InvalidInput
from oricf.models.tensors import clip

SHM_DIR = Path("/dev/shm")
REGION = "shared_memory_region"
OFFSET = "shared_memory_offset"
BYTE_SIZE = "shared_memory_byte_size"
PARAMETERS = (REGION, OFFSET, BYTE_SIZE)
_KEY = re.compile(r"/?[A-Za-z0-9_][A-Za-z0-9_.-]{0,199}")
_NAME = re.compile(r"[A-Za-z0-9_.:/-]{1,128}")
# Prefix of the objects ORICF's client creates: oricf_<pid>_<random>; a sweep removes those
# whose process is gone (created, then killed before the server opened them).
OWN_PREFIX = "oricf_"


def key_path(key: str) -> Path:
    """The file of a shared-memory key; InvalidInput for a key that is not a plain name."""
    if not _KEY.fullmatch(key):
        raise InvalidInput(f"shared-memory key '{clip(key)}': 1-200 letters, digits, '_', "
                           f"'-' or '.' after an optional '/' (no other '/', no leading '.')")
    return SHM_DIR / key.lstrip("/")


def check_region_name(name: str) -> str:
    if not _NAME.fullmatch(name):
        raise InvalidInput(f"shared-memory region name '{clip(name)}': 1-128 letters, "
                           f"digits or '_', '.', ':', '/', '-'")
    return name


@dataclass(frozen=True)
class SharedMemoryRef:
    """Where a tensor's bytes are: a registered region, an offset in it, a length."""

    region: str
    offset: int
    byte_size: int


def _integer(parameters: Mapping[str, Any], key: str, what: str) -> int:
    value = parameters[key].WhichOneof("parameter_choice")
    if value not in ("int64_param", "uint64_param"):
        raise InvalidInput(f"{what}: {key} must be an integer parameter")
    number = int(getattr(parameters[key], value))
    if number < 0:
        raise InvalidInput(f"{what}: {key} {number} is negative")
    return number


def tensor_ref(parameters: Mapping[str, Any], what: str) -> SharedMemoryRef | None:
    """A tensor's shared-memory parameters (an InferParameter map), None if it has none."""
    if not any(key in parameters for key in PARAMETERS):
        return None
    if REGION not in parameters or BYTE_SIZE not in parameters:
        raise InvalidInput(f"{what}: {REGION} and {BYTE_SIZE} go together")
    region = parameters[REGION]
    if region.WhichOneof("parameter_choice") != "string_param":
        raise InvalidInput(f"{what}: {REGION} must be a string parameter")
    offset = _integer(parameters, OFFSET, what) if OFFSET in parameters else 0
    return SharedMemoryRef(check_region_name(region.string_param), offset,
                           _integer(parameters, BYTE_SIZE, what))


class OwnedRegion:
    """A shared-memory object this process creates and writes; its name is removed once the
    server has it open (`release_name`), its memory when both sides have closed it."""

    def __init__(self, byte_size: int) -> None:
        self.byte_size = byte_size
        self.key = f"/{OWN_PREFIX}{os.getpid()}_{secrets.token_hex(6)}"
        self._path = key_path(self.key)
        fd = os.open(self._path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                     | os.O_CLOEXEC, 0o600)
        try:
            os.ftruncate(fd, byte_size)
            self._map = mmap.mmap(fd, byte_size)
        except BaseException:
            os.unlink(self._path)
            raise
        finally:
            os.close(fd)

    def write(self, data: bytes | memoryview, offset: int = 0) -> None:
        if offset + len(data) > self.byte_size:
            raise ValueError(f"{len(data):,} bytes at {offset} do not fit a region of "
                             f"{self.byte_size:,}")
        self._map[offset:offset + len(data)] = data

    def view(self, offset: int, size: int) -> memoryview:
        return memoryview(self._map)[offset:offset + size]

    def release_name(self) -> None:
        """Removes the object's name from /dev/shm; the memory stays while it is open."""
        self._path.unlink(missing_ok=True)

    def close(self) -> None:
        self.release_name()
        # A view still exported keeps the mapping: the memory goes with the last view.
        with contextlib.suppress(BufferError):
            self._map.close()


def owner_gone(key: str) -> bool:
    """Whether a key is one ORICF's client made in a process that no longer runs."""
    name = key.lstrip("/")
    pid = name[len(OWN_PREFIX):].split("_", 1)[0] if name.startswith(OWN_PREFIX) else ""
    return pid.isdigit() and not _alive(int(pid))


def sweep_orphans() -> list[str]:
    """Removes the objects ORICF's client created in processes that no longer run; their
    names."""
    removed = []
    for path in SHM_DIR.glob(f"{OWN_PREFIX}*_*"):
        if owner_gone(path.name):
            path.unlink(missing_ok=True)
            removed.append(path.name)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
