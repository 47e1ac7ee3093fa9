"""The regions of system shared memory that clients on this host registered with a server.

A region is a client's shared-memory object (a file in /dev/shm), held open by the server
from SystemSharedMemoryRegister to SystemSharedMemoryUnregister. Bytes move with pread and
pwrite on that file, never through a mapping: a client that shrinks its object after
registering gets a short read (INVALID_ARGUMENT), where a mapping would fault and kill the
server. Every access is checked against the registered bounds and the object's size.

The registry is bounded (regions, bytes). An object owned by another user, a link, or
anything but a plain file is refused: a client may only name memory it could write itself.
"""

from __future__ import annotations

import logging
import os
import stat
import threading
from dataclasses import dataclass, field

from pydantic import Field

from oricf.config import Schema
from oricf.errors import InvalidInput, Overloaded
from oricf.models.shared_memory import (
    SharedMemoryRef,
    check_region_name,
    key_path,
    owner_gone,
)
from oricf.models.tensors import clip

log = logging.getLogger(__name__)


class SharedMemorySettings(Schema):
    enabled: bool = Field(True, description="serve the system shared-memory extension")
    max_regions: int = Field(64, ge=1, le=4096, description="registered at once")
    max_total_mb: float = Field(1024, gt=0, le=65_536,
                                description="the registered regions' bytes together")


@dataclass
class Region:
    name: str
    key: str
    offset: int
    byte_size: int
    fd: int
    lock: threading.Lock = field(default_factory=threading.Lock)
    closed: bool = False


class SharedMemoryRegistry:
    def __init__(self, settings: SharedMemorySettings) -> None:
        self.settings = settings
        self._regions: dict[str, Region] = {}
        self._lock = threading.Lock()

    def register(self, name: str, key: str, offset: int, byte_size: int) -> None:
        check_region_name(name)
        path = key_path(key)
        if byte_size <= 0:
            raise InvalidInput(f"region '{name}': byte_size must be > 0")
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError as exc:
            raise InvalidInput(f"region '{name}': cannot open shared-memory key "
                               f"'{clip(key)}': {exc.strerror}") from None
        try:
            self._check_object(fd, name, key, offset, byte_size)
            with self._lock:
                if not self._fits(byte_size):
                    self._evict_orphans()
                self._check_room(name, byte_size)
                self._regions[name] = Region(name, key, offset, byte_size, fd)
        except BaseException:
            os.close(fd)
            raise
        log.debug("shared memory: region %s registered (%d bytes)", name, byte_size)

    def _check_object(self, fd: int, name: str, key: str, offset: int, byte_size: int
                      ) -> None:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise InvalidInput(f"region '{name}': key '{clip(key)}' is not a shared-memory "
                               f"object")
        if info.st_uid != os.getuid():
            raise InvalidInput(f"region '{name}': key '{clip(key)}' belongs to another user")
        if offset + byte_size > info.st_size:
            raise InvalidInput(f"region '{name}': offset {offset} + byte_size {byte_size} "
                               f"runs past the object's {info.st_size} bytes")

    def _fits(self, byte_size: int) -> bool:
        total = sum(r.byte_size for r in self._regions.values()) + byte_size
        return (len(self._regions) < self.settings.max_regions
                and total <= self.settings.max_total_mb * 2**20)

    def _evict_orphans(self) -> None:
        """Drops the regions of ORICF clients that died (SIGKILL gives them no time to
        unregister), so that a restarted client finds room. Only when room is needed: a
        client in another PID namespace (a container) may look dead from here."""
        for name in [n for n, r in self._regions.items() if owner_gone(r.key)]:
            region = self._regions.pop(name)
            with region.lock:
                region.closed = True
                os.close(region.fd)
            log.info("shared memory: region %s dropped: the process that made it is gone",
                     name)

    def _check_room(self, name: str, byte_size: int) -> None:
        if name in self._regions:
            raise InvalidInput(f"region '{name}' is already registered; unregister it first")
        if len(self._regions) >= self.settings.max_regions:
            raise Overloaded(f"{len(self._regions)} shared-memory regions registered, the "
                             f"most this server holds (shared_memory.max_regions)")
        total = sum(r.byte_size for r in self._regions.values()) + byte_size
        if total > self.settings.max_total_mb * 2**20:
            raise Overloaded(f"registering region '{name}' would hold {total / 2**20:,.0f} "
                             f"MB of shared memory, more than shared_memory.max_total_mb")

    def unregister(self, name: str) -> None:
        """Unregisters one region; an empty name: all. An unknown name is not an error
        (as in Triton)."""
        with self._lock:
            names = list(self._regions) if not name else [name] if name in self._regions \
                else []
            regions = [self._regions.pop(n) for n in names]
        for region in regions:
            with region.lock:  # no read or write is using the file any more
                region.closed = True
                os.close(region.fd)

    def status(self, name: str) -> list[Region]:
        with self._lock:
            if not name:
                return list(self._regions.values())
            if name not in self._regions:
                raise InvalidInput(f"no shared-memory region '{clip(name)}' is registered")
            return [self._regions[name]]

    def _region(self, ref: SharedMemoryRef) -> Region:
        with self._lock:
            region = self._regions.get(ref.region)
        if region is None:
            raise InvalidInput(f"no shared-memory region '{clip(ref.region)}' is registered")
        if ref.offset + ref.byte_size > region.byte_size:
            raise InvalidInput(f"region '{ref.region}': offset {ref.offset} + byte_size "
                               f"{ref.byte_size} runs past its {region.byte_size} bytes")
        return region

    def read(self, ref: SharedMemoryRef) -> bytes:
        """A copy of the referenced bytes (the client may change them afterwards)."""
        region = self._region(ref)
        with region.lock:
            if region.closed:
                raise InvalidInput(f"region '{ref.region}' was unregistered")
            data = os.pread(region.fd, ref.byte_size, region.offset + ref.offset)
        if len(data) != ref.byte_size:
            raise InvalidInput(f"region '{ref.region}': {len(data)} of {ref.byte_size} bytes "
                               f"could be read (the object shrank after it was registered)")
        return data

    def write(self, ref: SharedMemoryRef, data: bytes) -> None:
        """data into the referenced bytes; refused if it does not fit."""
        if len(data) > ref.byte_size:
            raise InvalidInput(f"region '{ref.region}': the output takes {len(data)} bytes, "
                               f"shared_memory_byte_size gives {ref.byte_size}")
        region = self._region(ref)
        with region.lock:
            if region.closed:
                raise InvalidInput(f"region '{ref.region}' was unregistered")
            size = os.fstat(region.fd).st_size
            start = region.offset + ref.offset
            if start + len(data) > size:  # never grow the client's object
                raise InvalidInput(f"region '{ref.region}': the object shrank after it "
                                   f"was registered")
            os.pwrite(region.fd, data, start)

    def close(self) -> None:
        self.unregister("")
