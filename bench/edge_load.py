"""The robots of `oricf bench edge` that are not gateway processes: a load generator in one
asyncio loop, one channel per robot, each a 10 fps camera with at most one frame in flight
(a frame captured while a call is out waits, and a newer one replaces it: dropped)."""

from __future__ import annotations

import asyncio
import random
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import grpc

from oricf.bench.common import JPEG_QUALITY, load_frames
from oricf.bench.edge_robot import FPS
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc

STARTUP_S = 8.0       # from spawning the robots to the window: imports, frames, channels


@dataclass
class Window:
    start: float  # epoch seconds
    seconds: float

    @property
    def end(self) -> float:
        return self.start + self.seconds

    def holds(self, t: float) -> bool:
        return self.start <= t < self.end


@dataclass
class Tally:
    """What happened to the frames captured in the window, over all robots."""

    captured: int = 0
    latencies: list[float] = field(default_factory=list)
    dropped: int = 0
    errors: int = 0

    def add(self, other: dict[str, Any]) -> None:
        self.captured += other["captured"]
        self.latencies += other["latencies"]
        self.dropped += other["dropped"]
        self.errors += other["errors"]


class VirtualRobot:
    """A camera at FPS and a sender with at most one frame in flight; the newest frame wins."""

    def __init__(self, requests: list[detector_pb2.DetectRequest], window: Window,
                 deadline_s: float, phase_s: float) -> None:
        self.requests = requests
        self.window = window
        self.deadline_s = deadline_s
        self.phase_s = phase_s
        self.tally = Tally()
        self._latest: tuple[int, float] | None = None
        self._ready = asyncio.Event()
        self._done = False

    async def camera(self, first: float) -> None:
        tick, i = first + self.phase_s, 0
        await asyncio.sleep(max(0.0, tick - time.time()))
        while tick < self.window.end + 0.5:
            if self._latest is not None and self.window.holds(self._latest[1]):
                self.tally.dropped += 1
            self._latest = (i, tick)
            self.tally.captured += self.window.holds(tick)
            self._ready.set()
            i, tick = i + 1, tick + 1 / FPS
            await asyncio.sleep(max(0.0, tick - time.time()))
        self._done = True
        self._ready.set()

    async def sender(self, stub: detector_pb2_grpc.DetectorStub) -> None:
        while True:
            if self._latest is None:
                if self._done:
                    return
                await self._ready.wait()
                self._ready.clear()
                continue
            (i, captured), self._latest = self._latest, None
            try:
                await stub.Detect(self.requests[i % len(self.requests)],
                                  timeout=self.deadline_s)
                if self.window.holds(captured):
                    self.tally.latencies.append(time.time() - captured)
            except grpc.aio.AioRpcError:
                self.tally.errors += self.window.holds(captured)


def jpeg_requests(count: int, offset: int) -> list[detector_pb2.DetectRequest]:
    requests = []
    for frame in load_frames(count + offset)[offset:]:
        data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])[1]
        image = common_pb2.Image(data=data.tobytes(), encoding="jpeg", width=frame.shape[1],
                                 height=frame.shape[0])
        requests.append(detector_pb2.DetectRequest(image=image, labels=["person"]))
    return requests


async def generate(address: str, robots: int, window: Window, deadline_s: float,
                   requests: list[detector_pb2.DetectRequest]) -> Tally:
    phases = random.Random(robots).sample(range(100), robots)  # cameras out of step
    fleet = [VirtualRobot(requests[i % 7:] + requests[:i % 7], window, deadline_s, p / 1e3)
             for i, p in enumerate(phases)]
    channels = [grpc.aio.insecure_channel(address) for _ in fleet]
    first = window.start - STARTUP_S / 2  # warm up before the window
    try:
        await asyncio.gather(*(r.camera(first) for r in fleet),
                             *(r.sender(detector_pb2_grpc.DetectorStub(c))
                               for r, c in zip(fleet, channels, strict=True)))
    finally:
        await asyncio.gather(*(c.close() for c in channels))
    total = Tally()
    for robot in fleet:
        total.add(robot.tally.__dict__)
    return total
