"""What runs a video input (oricf.gateway.sources.video declares it): video from a file,
an RTSP or HTTP stream, or a V4L2 device (FFmpeg through OpenCV), read on a thread of its
own.

The newest frame wins: the route takes frames as it can and the rest are dropped (the
route's worker keeps only the newest). `fps` caps how often frames are handed over: a
stream's extra frames are skipped, a file is played at that rate (without `fps`, as fast as
it decodes). A file ends the route at its end, or starts again with `loop`; a stream or
device that cannot be opened or stops sending is reopened with backoff: every reconnect
waits, and the wait grows until frames have flowed for STEADY_S (a camera that accepts and
drops each connection is not hammered); each attempt to open is logged, and the warnings a
broken stream repeats on every connection are throttled. RTSP runs over TCP unless
OPENCV_FFMPEG_CAPTURE_OPTIONS says otherwise (e.g. "rtsp_transport;udp"). An HTTP URL that
serves Motion JPEG is read without FFmpeg and its frames are handed on as the JPEG bytes
that came (mjpeg.py); any other URL, FFmpeg decodes.
URLs are logged without their user and password.

Each frame carries the time it was taken (values.FRAME_TIME): a file's frame, its position
in the file (the container's timestamps), so that tracking measures the video's time
however fast the file is read, each pass of a looping file following the last; a stream's
or device's frame, when it arrived.
"""

from __future__ import annotations

import http.client
import logging
import os
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from oricf.errors import InvalidInput
from oricf.gateway.sources.base import Submit
from oricf.gateway.sources.mjpeg import BadStream, MjpegStream, NotMjpeg, without_credentials
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import FRAME_TIME, Frame
from oricf.logs import quoted

if TYPE_CHECKING:
    from oricf.gateway.config import InputConfig

log = logging.getLogger(__name__)

RECONNECT_MIN_S = 0.5
RECONNECT_MAX_S = 10.0
STEADY_S = 10.0  # frames flowing this long make the next reconnect start from the shortest wait
STREAM_TIMEOUT_MS = 5000


# What a broken or stalled stream raises while it is read: the source reconnects.
STREAM_ERRORS = (OSError, http.client.HTTPException, BadStream, InvalidInput)


class Capture(Protocol):
    # Where the frame just read lies in a file (s); None for a stream or device.
    position_s: float | None

    def read(self) -> Frame | None: ...   # None: the source ended

    def release(self) -> None: ...


class FfmpegCapture:
    """OpenCV's VideoCapture (FFmpeg, V4L2) as frames of decoded pixels."""

    def __init__(self, capture: Any, file: bool = False) -> None:
        import cv2

        self._capture = capture
        self._file = file
        self._fps = capture.get(cv2.CAP_PROP_FPS) if file else 0.0
        self._msec = cv2.CAP_PROP_POS_MSEC
        self.position_s: float | None = None

    def read(self) -> Frame | None:
        ok, pixels = self._capture.read()
        if ok and self._file:
            self.position_s = self._position(self.position_s)
        return Frame.from_pixels(pixels) if ok else None

    def _position(self, previous: float | None) -> float | None:
        """The container's timestamp of the frame just read; for a container without them
        (each the same), one frame period on from the previous frame."""
        seconds = self._capture.get(self._msec) / 1e3
        if previous is None or seconds > previous:
            return seconds
        return previous + 1 / self._fps if self._fps > 0 else None

    def release(self) -> None:
        self._capture.release()


def is_live(url: str) -> bool:
    """A stream or device (reconnect when it drops) rather than a file (it ends)."""
    return url.startswith(("rtsp://", "rtsps://", "http://", "https://", "/dev/video"))


class VideoSource:
    def __init__(self, route: str, config: InputConfig, submit: Submit,
                 on_end: Callable[[str], None]) -> None:
        assert config.url is not None
        self.route = route
        self.url = config.url
        self.shown_url = without_credentials(config.url)
        self._open_error = ""  # why the last attempt to open failed, when it is known
        self.config = config
        self.frames = 0
        self.reconnects = 0
        self._submit = submit
        self._on_end = on_end
        self._stop = threading.Event()
        self._throttle = ThrottledLog(log)
        # A file's frame times: passes of a looping file follow each other in time.
        self._pass_start = True
        self._offset = 0.0
        self._last_time: tuple[float | None, float] = (None, 0.0)  # (last frame, its step)
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"video-{route}")

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def _open(self) -> Capture | None:
        self._open_error = ""
        if self.url.startswith(("http://", "https://")):
            try:
                return MjpegStream(self.url, STREAM_TIMEOUT_MS / 1e3, self._stop)
            except NotMjpeg:
                pass  # another kind of stream: FFmpeg reads it
            except STREAM_ERRORS as exc:
                self._open_error = f" ({quoted(exc)})"  # a server's words: escaped
                return None
        import cv2

        if self.url.startswith("/dev/video") and self.url[len("/dev/video"):].isdigit():
            capture = cv2.VideoCapture(int(self.url[len("/dev/video"):]))  # V4L2 device N
        elif is_live(self.url):
            # RTSP over TCP: no frames lost to UDP, and a server that goes away is noticed at
            # once; a stream that stalls is given up after the read timeout. One decoder
            # thread: FFmpeg's frame threading holds back a frame per thread, which a
            # robot feels as latency (`oricf bench rtsp` measures it).
            os.environ.setdefault("OPENCV_FFMPEG_CAPTURE_OPTIONS", "rtsp_transport;tcp")
            capture = cv2.VideoCapture(self.url, cv2.CAP_FFMPEG, [
                cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, STREAM_TIMEOUT_MS,
                cv2.CAP_PROP_READ_TIMEOUT_MSEC, STREAM_TIMEOUT_MS,
                cv2.CAP_PROP_N_THREADS, 1])
        else:
            capture = cv2.VideoCapture(os.path.expanduser(self.url))
        return FfmpegCapture(capture, not is_live(self.url)) if capture.isOpened() else None

    def _run(self) -> None:
        backoff = RECONNECT_MIN_S
        while not self._stop.is_set():
            capture = self._open()
            if capture is None:
                if not is_live(self.url):
                    log.error("route %s: cannot open %s; the route ends", self.route,
                              self.shown_url)
                    break
                self.reconnects += 1
                log.warning("route %s: cannot open %s%s; trying again in %.1f s", self.route,
                            self.shown_url, self._open_error, backoff)
            else:
                opened, frames = time.monotonic(), self.frames
                ended = self._session(capture)
                if self._stop.is_set() or (ended and not is_live(self.url)
                                           and not self.config.loop):
                    if ended and not self._stop.is_set():
                        log.info("route %s: %s ended after %d frames", self.route,
                                 self.shown_url, self.frames)
                    break
                if not is_live(self.url):
                    continue  # a looping file starts again at once
                if self.frames > frames and time.monotonic() - opened >= STEADY_S:
                    backoff = RECONNECT_MIN_S
                self.reconnects += 1
                self._throttle.warning("stopped", "route %s: %s stopped sending; reconnecting "
                                       "in %.1f s", self.route, self.shown_url, backoff)
            self._stop.wait(backoff)
            backoff = min(backoff * 2, RECONNECT_MAX_S)
        self._on_end(self.route)

    def _session(self, capture: Capture) -> bool:
        """Reads an opened capture until it ends or fails (True) or the source stops (False)."""
        if self.reconnects or is_live(self.url):
            log.info("route %s: %s opened", self.route, self.shown_url)
        try:
            return self._read(capture)
        except STREAM_ERRORS as exc:
            if not self._stop.is_set():
                self._throttle.warning(f"error:{type(exc).__name__}", "route %s: %s: %s",
                                       self.route, self.shown_url, quoted(exc))
            return True
        finally:
            capture.release()

    def _read(self, capture: Capture) -> bool:
        """Hands frames over until the source ends (True) or the source is stopped (False)."""
        self._pass_start = True
        period = 1.0 / self.config.fps if self.config.fps else 0.0
        next_at = time.monotonic()
        while not self._stop.is_set():
            frame = capture.read()
            if frame is None:
                return True
            now = time.monotonic()
            if period and now < next_at:
                if is_live(self.url):
                    continue  # over the rate cap: a stream's extra frames are skipped
                self._stop.wait(next_at - now)  # a file plays at the capped rate
                now = time.monotonic()
            next_at = max(next_at + period, now) if period else now
            self.frames += 1
            taken = self._frame_time(capture.position_s)
            self._submit(lambda f=frame, t=taken: {"image": f, FRAME_TIME: t})
        return False

    def _frame_time(self, position: float | None) -> float:
        """When a frame was taken: its position in a file (each pass of a looping file
        following the last one), or when it arrived from a stream or device."""
        if position is None:
            return time.monotonic()
        if self._pass_start:  # the file starts (again)
            self._pass_start = False
            last, step = self._last_time
            self._offset = (last + step - position) if last is not None else 0.0
        taken = self._offset + position
        last, step = self._last_time
        self._last_time = (taken, taken - last if last is not None and taken > last else step)
        return taken
