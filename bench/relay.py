"""A TCP relay that delays every chunk by a fixed time plus random jitter, in order: the
delay and jitter this kernel cannot add (it has no netem). Listens on 127.0.0.1."""

from __future__ import annotations

import contextlib
import heapq
import random
import socket
import threading
import time


class DelayRelay:
    def __init__(self, upstream: tuple[str, int], delay_s: float, jitter_s: float = 0.0
                 ) -> None:
        self.upstream = upstream
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._closed = threading.Event()
        self._sockets: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True, name="relay-accept").start()

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            try:
                server = socket.create_connection(self.upstream, timeout=5)
            except OSError:
                client.close()
                continue
            server.settimeout(None)
            self._sockets += [client, server]
            for source, sink in ((client, server), (server, client)):
                threading.Thread(target=self._pump, args=(source, sink), daemon=True).start()

    def _pump(self, source: socket.socket, sink: socket.socket) -> None:
        """Reads chunks and sends each when its time comes; never before the one before it."""
        pending: list[tuple[float, int, bytes]] = []
        ready = threading.Condition()
        done = threading.Event()

        def sender() -> None:
            while True:
                with ready:
                    while not pending and not done.is_set():
                        ready.wait()
                    if not pending:
                        break
                    due, _, chunk = pending[0]
                    wait = due - time.monotonic()
                    if wait > 0:
                        ready.wait(wait)
                        continue
                    heapq.heappop(pending)
                try:
                    sink.sendall(chunk)
                except OSError:
                    break
            with contextlib.suppress(OSError):
                sink.shutdown(socket.SHUT_WR)

        threading.Thread(target=sender, daemon=True).start()
        last_due, order = 0.0, 0
        while True:
            try:
                chunk = source.recv(65536)
            except OSError:
                break
            if not chunk:
                break
            due = max(last_due, time.monotonic() + self.delay_s
                      + random.uniform(-self.jitter_s, self.jitter_s))
            last_due, order = due, order + 1
            with ready:
                heapq.heappush(pending, (due, order, chunk))
                ready.notify()
        done.set()
        with ready:
            ready.notify()

    def close(self) -> None:
        self._closed.set()
        self._listener.close()
        for sock in self._sockets:
            with contextlib.suppress(OSError):
                sock.close()
