"""Camera frames and tensors to a service on this host through system shared memory
instead of the socket (an endpoint's `image.transport: shm` or `auto`).

Each route that sends frames keeps a small ring of regions per target: shared-memory
objects this process creates, registers with the server (the Open Inference Protocol's
SystemSharedMemoryRegister, which `oricf serve models` and the detector serve) and then
unlinks from /dev/shm, so nothing is left there whichever side dies. A call writes into the
next free slot and names it; the server reads it with one copy.

When a target cannot take shared memory (not on this host, the service does not offer it,
registration refused) the call goes on the wire, and the reason is logged once. A server
that restarted has forgotten the regions: such a call is answered INVALID_ARGUMENT naming
an unregistered region, and the ring is registered again on the next call.
"""

from __future__ import annotations

import itertools
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import grpc

from oricf.hosts import is_loopback_address
from oricf.models.shared_memory import OwnedRegion, SharedMemoryRef, sweep_orphans
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc

log = logging.getLogger(__name__)
T = TypeVar("T")
# What a call puts in shared memory: bytes to write, or the size to keep for an output.
Payload = bytes | memoryview | int

SHARED = ("shm", "auto")  # the image transports that use shared memory
RING_SLOTS = 2  # a frame being read by the server while the next one is written
REGISTER_TIMEOUT_S = 2.0
IN_USE_POLL_S = 0.01  # how often to ask again while a server says a region is in use
# Refusals that may pass (a server starting, busy or full): the wire now, another try later.
PASSING = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED,
                     grpc.StatusCode.RESOURCE_EXHAUSTED})
_names = itertools.count()
_swept = threading.Event()


@dataclass
class Slot:
    region: OwnedRegion
    name: str
    lock: threading.Lock = field(default_factory=threading.Lock)


@dataclass
class Ring:
    slots: list[Slot]
    next: int = 0


class SharedMemoryTransport:
    """The rings of one route, one per target that takes shared memory."""

    def __init__(self, owner: str, mode: str) -> None:
        """owner: names the regions (endpoint and route); mode: shm (any target) or auto
        (loopback targets only)."""
        self.owner = owner
        self.mode = mode
        self._rings: dict[str, Ring | str] = {}  # target address -> ring, or why not
        self._lock = threading.Lock()
        if not _swept.is_set():
            _swept.set()
            removed = sweep_orphans()
            if removed:
                log.info("shared memory: removed %d objects left by processes that died",
                         len(removed))

    def place(self, target: Any, payloads: list[int]) -> tuple[Slot, list[SharedMemoryRef]] | None:
        """A free slot of the target's ring, locked until release(), and where each payload
        (by size) goes in it; None when the call must go on the wire."""
        ring = self._ring(target, payloads)
        if ring is None:
            return None
        with self._lock:
            for _ in range(len(ring.slots)):
                slot = ring.slots[ring.next]
                ring.next = (ring.next + 1) % len(ring.slots)
                if slot.lock.acquire(blocking=False):
                    break
            else:
                return None  # every slot in use: this call goes on the wire
        refs, offset = [], 0
        for size in payloads:
            refs.append(SharedMemoryRef(slot.name, offset, size))
            offset += size
        return slot, refs

    def call(self, target: Any, rpc: str, timeout: float, payloads: Sequence[Payload],
             build: Callable[[list[SharedMemoryRef] | None], Any],
             finish: Callable[[Any, OwnedRegion | None], T]) -> T:
        """Calls rpc on target with the payloads (bytes to write, or a size to keep free for
        an output) in a slot of its ring: build(where each payload is) makes the request,
        finish(response, region) reads the answer while the slot is still held. On the
        wire (build(None), finish(response, None)) when shared memory is not possible, and
        once more on the wire if the server lost the regions."""
        sizes = [p if isinstance(p, int) else len(p) for p in payloads]
        placed = self.place(target, sizes)
        if placed is None:
            return finish(target.invoke(rpc, build(None), timeout), None)
        slot, refs = placed
        try:
            for payload, ref in zip(payloads, refs, strict=True):
                if not isinstance(payload, int):
                    slot.region.write(payload, ref.offset)
            try:
                return finish(target.invoke(rpc, build(refs), timeout), slot.region)
            except grpc.RpcError as exc:
                if not lost_regions(exc):
                    raise
                log.info("%s: %s forgot its shared-memory regions (restarted?); they are "
                         "registered again on the next call", self.owner, target.address)
        finally:
            slot.lock.release()
        self.forget(target)
        return finish(target.invoke(rpc, build(None), timeout), None)

    def forget(self, target: Any) -> None:
        """The server lost the regions (it restarted): register a new ring next time."""
        with self._lock:
            ring = self._rings.pop(target.address, None)
        if isinstance(ring, Ring):
            for slot in ring.slots:
                slot.region.close()

    def _ring(self, target: Any, payloads: list[int]) -> Ring | None:
        needed = sum(payloads)
        with self._lock:
            ring = self._rings.get(target.address)
        if isinstance(ring, str):
            return None
        if ring is not None and ring.slots[0].region.byte_size >= needed:
            return ring
        if ring is not None:  # frames grew: a bigger ring
            self._unregister(target, ring)
            self.forget(target)
        if self.mode == "auto" and not is_loopback_address(target.address):
            self._refuse(target, "it is not on this host (a loopback address)")
            return None
        try:
            ring = self._register(target, needed)
        except grpc.RpcError as exc:
            if exc.code() in PASSING and not restricted(exc):  # not now: the call will tell
                log.debug("%s: registering with %s: %s", self.owner, target.address,
                          exc.code().name)
                return None
            self._refuse(target, f"{exc.code().name}: {exc.details()}")
            return None
        except OSError as exc:
            self._refuse(target, f"cannot create shared memory: {exc}")
            return None
        with self._lock:
            self._rings[target.address] = ring
        return ring

    def _refuse(self, target: Any, why: str) -> None:
        with self._lock:
            self._rings[target.address] = why
        log.info("%s: shared memory to %s is not possible (%s); frames go on the wire",
                 self.owner, target.address, why)

    def _register(self, target: Any, byte_size: int) -> Ring:
        stub = oip_grpc.GRPCInferenceServiceStub(target.channel)
        slots = []
        try:
            for _ in range(RING_SLOTS):
                region = OwnedRegion(byte_size)
                name = f"{self.owner}-{os.getpid()}-{next(_names)}"
                slots.append(Slot(region, name))
                stub.SystemSharedMemoryRegister(
                    oip.SystemSharedMemoryRegisterRequest(name=name, key=region.key,
                                                          byte_size=byte_size),
                    timeout=REGISTER_TIMEOUT_S, metadata=target.metadata)
                region.release_name()  # the server holds it open: no name left behind
        except BaseException:
            self._unregister(target, Ring(slots))
            for slot in slots:
                slot.region.close()
            raise
        log.info("%s: %d shared-memory regions of %d bytes registered with %s", self.owner,
                 len(slots), byte_size, target.address)
        return Ring(slots)

    @staticmethod
    def _unregister(target: Any, ring: Ring) -> None:
        stub = oip_grpc.GRPCInferenceServiceStub(target.channel)
        for slot in ring.slots:
            deadline = time.monotonic() + REGISTER_TIMEOUT_S
            while True:
                try:
                    stub.SystemSharedMemoryUnregister(
                        oip.SystemSharedMemoryUnregisterRequest(name=slot.name),
                        timeout=REGISTER_TIMEOUT_S, metadata=target.metadata)
                    break
                except grpc.RpcError as exc:
                    # A server that is gone or forgot the region holds nothing of it; one
                    # still answering the last call through it (Triton) lets go shortly.
                    if not in_use(exc) or time.monotonic() > deadline:
                        break
                    time.sleep(IN_USE_POLL_S)

    def close(self, targets: list[Any]) -> None:
        for target in targets:
            with self._lock:
                ring = self._rings.get(target.address)
            if isinstance(ring, Ring):
                self._unregister(target, ring)
            self.forget(target)


def lost_regions(exc: grpc.RpcError) -> bool:
    """The server no longer knows a region the call named (it restarted): ORICF's servers
    answer INVALID_ARGUMENT naming an unregistered shared-memory region, Triton NOT_FOUND
    ("Unable to find shared memory region")."""
    details = exc.details() or ""
    return ((exc.code() == grpc.StatusCode.INVALID_ARGUMENT
             and "shared-memory region" in details)
            or (exc.code() == grpc.StatusCode.NOT_FOUND
                and "shared memory region" in details))


def in_use(exc: grpc.RpcError) -> bool:
    """Triton's refusal to unregister a region that the response it has just sent still
    holds (it lets go after the call ends): INTERNAL, "it is currently in use"."""
    return (exc.code() == grpc.StatusCode.INTERNAL
            and "currently in use" in (exc.details() or ""))


def restricted(exc: grpc.RpcError) -> bool:
    """Triton's answer when its shared-memory protocol needs an access token that the call
    did not carry (`--grpc-restricted-protocol`, on by default under pytriton): UNAVAILABLE,
    which would otherwise pass for a server not ready yet and be tried on every call."""
    return (exc.code() == grpc.StatusCode.UNAVAILABLE
            and (exc.details() or "").startswith("This protocol is restricted"))
