"""A control loop's observation: the newest message of each of its state topics, each part
no older than `max_age_ms`, joined into one state vector in the order the parts are listed,
and the newest image of each of the policy's cameras, as old at most (the parts and the
message types they read: oricf.gateway.control.parts).

A part that has not arrived, is too old, has the wrong length or a value that is not finite
as the policy is sent it (float32: 1e300 is finite as float64, infinite there; such a
message is refused as it arrives) makes the observation missing: the loop then asks nothing
and runs out what it has queued. So does a camera whose newest image is missing, too old, or
not an image. The images are kept as the transport made them (the gateway: frames as they
came, decoded only by the policy), by the name of the policy's camera each feeds.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.control.parts import CameraPart, StatePart, values_of

ImageOf = Callable[[str, Any], Any]  # (a camera's message type, the message) -> its image


class MissingState(Exception):
    """No observation now; the message says which part and why."""


@dataclass
class Latest:
    values: Any           # a state part's values (np.ndarray), or a camera's image
    received_ns: int


@dataclass(frozen=True)
class Observed:
    """One observation: the state vector, each camera's image, and when the oldest of its
    parts was received."""

    state: np.ndarray
    images: dict[str, Any]
    received_ns: int


def as_sent(values: np.ndarray, what: str = "state") -> np.ndarray:
    """State values as the policy is sent them (float32), or ValueError naming the first
    that is not finite there: a float64 beyond float32's range is infinity after the cast."""
    with np.errstate(over="ignore"):
        sent = np.asarray(values).astype(np.float32)
    bad = np.flatnonzero(~np.isfinite(sent))
    if bad.size:
        raise ValueError(f"{what}[{bad[0]}] is {values[bad[0]]}: not finite as float32")
    return sent


class Observation:
    """Thread-safe: message callbacks `take`, the loop's thread `assemble`s."""

    def __init__(self, parts: list[StatePart], size: int, max_age_ms: float,
                 cameras: list[CameraPart] | None = None,
                 image_of: ImageOf = lambda type_, msg: msg) -> None:
        """`size`: the state's length, -1 when the parts do not say; `image_of`: a camera's
        message (of its type) as the image kept, raising what `take` refuses."""
        self.parts = parts
        self.cameras = cameras or []
        self._image_of = image_of
        self.size = size
        self.max_age_ns = int(max_age_ms * 1e6)
        self.refused = 0          # messages whose values could not be used
        self._latest: list[Latest | None] = [None] * len(parts)
        self._images: list[Latest | None] = [None] * len(self.cameras)
        self._lock = threading.Lock()

    def take_image(self, index: int, msg: Any, received_ns: int | None = None) -> None:
        """Camera `index`'s message: its image kept as the newest, or MissingState naming
        why not (the camera's last good image is not used on)."""
        camera = self.cameras[index]
        try:
            image = self._image_of(camera.type, msg)
        except (InvalidInput, TypeError, ValueError, AttributeError) as exc:
            with self._lock:
                self.refused += 1
                self._images[index] = None
            raise MissingState(f"{camera.topic}: {exc}") from None
        with self._lock:
            self._images[index] = Latest(image, received_ns or time.monotonic_ns())

    def newest_image(self, index: int) -> Any | None:
        """Camera `index`'s newest image kept (None: none, or the last was refused)."""
        with self._lock:
            got = self._images[index]
        return None if got is None else got.values

    def take(self, index: int, msg: Any, received_ns: int | None = None) -> None:
        part = self.parts[index]
        try:
            values = values_of(part, msg)
            as_sent(values, "value")  # refused here, naming the topic, not sent as infinity
        except (TypeError, ValueError, AttributeError) as exc:  # not what its type says
            with self._lock:
                self.refused += 1
                self._latest[index] = None  # the part's last good value is not used on
            raise MissingState(f"{part.topic}: {exc}") from None
        with self._lock:
            self._latest[index] = Latest(values, received_ns or time.monotonic_ns())

    def assemble(self, now_ns: int) -> Observed:
        """The state vector, the images and when the oldest part was received, or
        MissingState."""
        with self._lock:
            latest = list(self._latest)
            images = list(self._images)
        topics = [part.topic for part in self.parts] + [c.topic for c in self.cameras]
        for topic, got in zip(topics, latest + images, strict=True):
            self._fresh(topic, got, now_ns)
        state = np.concatenate([got.values for got in latest if got is not None])
        if self.size >= 0 and state.size != self.size:
            raise MissingState(f"the state parts give {state.size} values, the policy takes "
                               f"{self.size}")
        oldest = min(got.received_ns for got in latest + images if got is not None)
        return Observed(state, {camera.name: got.values for camera, got
                                in zip(self.cameras, images, strict=True) if got is not None},
                        oldest)

    def _fresh(self, topic: str, got: Latest | None, now_ns: int) -> None:
        if got is None:
            raise MissingState(f"{topic}: nothing received")
        age_ns = now_ns - got.received_ns
        if age_ns > self.max_age_ns:
            raise MissingState(f"{topic}: the newest message is {age_ns / 1e6:.0f} ms old "
                               f"(max_age_ms {self.max_age_ns / 1e6:g})")
