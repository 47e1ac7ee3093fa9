"""Opening a camera's HTTP stream, as mjpeg.py reads it.

Two things urllib does not do by itself. Redirects: the `Authorization` header (the user and
password of the camera's URL) follows a redirect only within the camera's own origin
(scheme, host and port), as browsers and curl do, so a camera (or whoever answers for it)
cannot send the password to another host. Deadlines: a socket timeout bounds one wait, and a
camera that drips a byte a second never trips it; a watchdog thread shuts the connection
down when the step being read (the answer, a part's headers, a part) is overdue, or when the
reader is stopped, which wakes a blocked read at once.
"""

from __future__ import annotations

import contextlib
import http.client
import math
import socket
import threading
import time
import urllib.parse
import urllib.request
from typing import Any

POLL_S = 0.1  # how soon the watchdog notices a deadline or a stop


def origin(url: str) -> tuple[str, str, int | None]:
    """(scheme, host, port) with the scheme's default port filled in."""
    parts = urllib.parse.urlsplit(url)
    scheme = parts.scheme.lower()
    try:
        port = parts.port
    except ValueError:  # not a port: an origin of its own, equal to none
        return scheme, "", -1
    return scheme, (parts.hostname or "").lower(), port or {"http": 80, "https": 443}.get(scheme)


class SameOriginCredentials(urllib.request.HTTPRedirectHandler):
    """Follows HTTP(S) redirects only, and takes the credentials along only to the same
    origin."""

    def redirect_request(self, req: urllib.request.Request, fp: Any, code: int, msg: str,
                         headers: Any, newurl: str) -> urllib.request.Request | None:
        if urllib.parse.urlsplit(newurl).scheme.lower() not in ("http", "https"):
            return None  # not followed: the redirect is reported as the HTTP error it is
        new = super().redirect_request(req, fp, code, msg, headers, newurl)
        if new is not None and origin(newurl) != origin(req.full_url):
            new.remove_header("Authorization")
        return new


class Watchdog:
    """Shuts the connection down when the current step is overdue (`expired` then says so)
    or when `stopped` is set."""

    def __init__(self, stopped: threading.Event | None = None) -> None:
        self.expired = False
        self._stopped = stopped
        self._due = math.inf
        self._sock: socket.socket | None = None
        self._cut = False
        self._lock = threading.Lock()
        self._done = threading.Event()
        threading.Thread(target=self._watch, daemon=True, name="http-stream-watchdog").start()

    def arm(self, seconds: float) -> None:
        """The next step must be read within `seconds` from now."""
        self._due = time.monotonic() + seconds

    def attach(self, sock: socket.socket) -> None:
        with self._lock:
            self._sock = sock
            cut = self._cut
        if cut:
            self._shutdown(sock)

    def close(self) -> None:
        self._done.set()

    def _watch(self) -> None:
        while not self._done.wait(POLL_S):
            overdue = time.monotonic() > self._due
            if overdue or (self._stopped is not None and self._stopped.is_set()):
                self.expired = overdue
                with self._lock:
                    self._cut = True
                    sock = self._sock
                if sock is not None:
                    self._shutdown(sock)
                return

    @staticmethod
    def _shutdown(sock: socket.socket) -> None:
        # The plain socket's shutdown, also under TLS: it only ends the connection, and
        # the thread blocked in a read sees the end of the stream.
        with contextlib.suppress(OSError):
            socket.socket.shutdown(sock, socket.SHUT_RDWR)


def _watched(base: type[http.client.HTTPConnection], watchdog: Watchdog) -> Any:
    class Watched(base):  # type: ignore[misc, valid-type]
        def connect(self) -> None:
            super().connect()
            watchdog.attach(self.sock)

    return Watched


class _Http(urllib.request.HTTPHandler):
    def __init__(self, watchdog: Watchdog) -> None:
        super().__init__()
        self._connection = _watched(http.client.HTTPConnection, watchdog)

    def http_open(self, req: urllib.request.Request) -> Any:
        return self.do_open(self._connection, req)


class _Https(urllib.request.HTTPSHandler):
    def __init__(self, watchdog: Watchdog) -> None:
        super().__init__()
        self._connection = _watched(http.client.HTTPSConnection, watchdog)

    def https_open(self, req: urllib.request.Request) -> Any:
        return self.do_open(self._connection, req,
                            context=getattr(self, "_context", None))


def open_stream(url: str, headers: dict[str, str], timeout_s: float,
                watchdog: Watchdog) -> Any:
    """The response to GET url (redirects followed), its connection watched by `watchdog`."""
    opener = urllib.request.build_opener(SameOriginCredentials, _Http(watchdog),
                                         _Https(watchdog))
    return opener.open(urllib.request.Request(url, headers=headers), timeout=timeout_s)
