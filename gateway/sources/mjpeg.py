"""Motion JPEG over HTTP (multipart/x-mixed-replace, as IP cameras and camera bridges serve
it), read part by part and handed on as the JPEG bytes that came: a route that sends frames
to an edge detector as JPEG then neither decodes nor encodes them on the robot (through
FFmpeg, each frame would be decoded, and encoded again for the link).

A part is checked from its own JPEG header (the size read before anything is decoded); a
part that is not a JPEG is skipped and counted, a part larger than MAX_PART_BYTES (a lying
Content-Length included), or a malformed part header (more than MAX_HEADERS lines too) ends
the connection, and the video source reconnects with backoff. So does a camera too slow to
answer, to send a part's headers, or to send a part (each within the timeout, however the
bytes trickle in: http_stream.Watchdog). Credentials follow a redirect only within the
camera's origin (http_stream.SameOriginCredentials).
"""

from __future__ import annotations

import base64
import logging
import threading
import urllib.parse
from collections.abc import Callable
from typing import Any

from oricf.errors import InvalidInput
from oricf.gateway.sources.http_stream import Watchdog, open_stream
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Frame
from oricf.imaging import check_size, encoded_size

log = logging.getLogger(__name__)

MAX_PART_BYTES = 16 * 1024 * 1024
MAX_LINE = 4096          # a part header line, or a step while scanning for the boundary
MAX_HEADERS = 32        # lines of one part's header block

# One camera that sends bad parts on every connection must not fill the log.
_skips = ThrottledLog(log)


class NotMjpeg(Exception):
    """The URL answers, but not with multipart JPEG parts: FFmpeg reads it instead."""


class BadStream(Exception):
    """The stream broke its own format: the connection is dropped and opened again."""


def without_credentials(url: str) -> str:
    """The URL as it may be logged: user and password removed."""
    parts = urllib.parse.urlsplit(url)
    if parts.username is None and parts.password is None:
        return url
    host = parts.hostname or ""
    netloc = f"[{host}]" if ":" in host else host
    if parts.port is not None:
        netloc += f":{parts.port}"
    return urllib.parse.urlunsplit(parts._replace(netloc=netloc))


class MjpegStream:
    """One connection to an MJPEG URL; read() returns the next JPEG frame, None at the end."""

    position_s: float | None = None  # a stream: frames are timed when they arrive

    def __init__(self, url: str, timeout_s: float,
                 stopped: threading.Event | None = None) -> None:
        parts = urllib.parse.urlsplit(url)
        headers = {"Accept": "multipart/x-mixed-replace, image/jpeg"}
        if parts.username is not None:  # http://user:password@camera/...: basic auth
            secret = f"{urllib.parse.unquote(parts.username)}:" \
                     f"{urllib.parse.unquote(parts.password or '')}"
            headers["Authorization"] = "Basic " + base64.b64encode(secret.encode()).decode()
        self.shown_url = without_credentials(url)
        self._timeout = timeout_s
        self._watchdog = Watchdog(stopped)
        self._watchdog.arm(timeout_s)
        try:
            self._response: Any = open_stream(self.shown_url, headers, timeout_s,
                                              self._watchdog)
        except BaseException as exc:
            self._watchdog.close()
            if self._watchdog.expired:
                raise BadStream(f"no answer in {timeout_s:g} s") from exc
            raise
        message = self._response.headers
        boundary = message.get_param("boundary")
        if message.get_content_type() != "multipart/x-mixed-replace" or \
                not isinstance(boundary, str) or not boundary.strip('"'):
            self.release()
            raise NotMjpeg(message.get_content_type())
        token = boundary.strip('"').encode()
        # RFC 2046 puts "--" before the boundary; some cameras declare it with the dashes.
        self._delimiters = {b"--" + token, token}
        self._ends = {d + b"--" for d in self._delimiters}
        self._at_part = False  # the delimiter was read already (a part without a length)
        self.skipped = 0       # parts that were not JPEG images

    def read(self) -> Frame | None:
        while True:
            self._watchdog.arm(self._timeout)  # for the header block
            if not self._at_part and not self._find_delimiter():
                return None
            self._at_part = False
            data = self._part()
            if data is None:
                return None
            try:
                kind, width, height = encoded_size(data)
                if kind != "jpeg":
                    raise InvalidInput(f"a {kind.upper()} image")
                check_size(width, height)
            except InvalidInput as exc:
                self.skipped += 1
                _skips.warning(f"skipped:{self.shown_url}", "a part of the MJPEG stream %s "
                               "was skipped (%s); %d so far on this connection",
                               self.shown_url, exc, self.skipped)
                continue
            return Frame(data, "jpeg", width, height)

    def release(self) -> None:
        self._watchdog.close()
        self._response.close()

    def _watched(self, read: Callable[[int], bytes], size: int) -> bytes:
        """read(size), as a BadStream if the watchdog cut the connection for being late."""
        try:
            data = read(size)
        except OSError as exc:
            if self._watchdog.expired:
                raise BadStream(f"a part took over {self._timeout:g} s") from exc
            raise
        if self._watchdog.expired:
            raise BadStream(f"a part took over {self._timeout:g} s")
        return data

    def _line(self) -> bytes | None:
        return self._watched(self._response.readline, MAX_LINE) or None

    def _find_delimiter(self) -> bool:
        """Skips to the line after the next delimiter; False at the end of the stream."""
        scanned = 0
        while (line := self._line()) is not None:
            text = line.strip()
            if text in self._delimiters:
                return True
            if text in self._ends:
                return False
            scanned += len(line)
            if scanned > MAX_PART_BYTES:
                raise BadStream(f"no boundary in {MAX_PART_BYTES:,} bytes")
        return False

    def _part(self) -> bytes | None:
        """The body of the part whose delimiter was just read; None if the stream ended."""
        fields: dict[bytes, bytes] = {}
        for _ in range(MAX_HEADERS + 1):  # lines, not names: a name may come again and again
            line = self._line()
            if line is None:
                return None
            if not line.strip():
                break
            name, sep, value = line.partition(b":")
            if not sep:
                raise BadStream("malformed part header")
            fields[name.strip().lower()] = value.strip()
        else:
            raise BadStream(f"malformed part header (over {MAX_HEADERS} lines)")
        length = fields.get(b"content-length")
        if length is None:
            return self._until_delimiter()
        if not length.isdigit() or int(length) > MAX_PART_BYTES:
            raise BadStream(f"part Content-Length {length[:20]!r} refused (at most "
                            f"{MAX_PART_BYTES:,} bytes)")
        self._watchdog.arm(self._timeout)  # for the part itself
        data = self._watched(self._response.read, int(length))
        return data if len(data) == int(length) else None

    def _until_delimiter(self) -> bytes | None:
        """A part without Content-Length: everything up to the next delimiter line."""
        chunks: list[bytes] = []
        size = 0
        while (line := self._line()) is not None:
            if line.strip() in self._delimiters:
                self._at_part = True
                break
            if line.strip() in self._ends:
                break
            chunks.append(line)
            size += len(line)
            if size > MAX_PART_BYTES:
                raise BadStream(f"part over {MAX_PART_BYTES:,} bytes")
        else:
            return None
        data = b"".join(chunks)
        return data[:-2] if data.endswith(b"\r\n") else data.removesuffix(b"\n")
