"""The cost of the live view in `oricf bench gateway`: the onboard gateway's CPU per
processed frame with no live view, with the live view and nobody watching, and with one
viewer subscribed to every channel (a Python viewer on `websockets` that reads everything,
in a process of its own), at the view's default frame cap. With a viewer, raw camera frames
are JPEG-encoded for it (at most max_fps of them); nobody watching, they are not."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from oricf.bench.common import print_table
from oricf.bench.gateway_report import InputResult
from oricf.gateway.listeners import LiveViewConfig


def view_overlay(overlay: dict[str, Any], port: int) -> dict[str, Any]:
    """A benchmark gateway overlay with the live view on 127.0.0.1:port."""
    overlay["foxglove"] = {"listen": f"127.0.0.1:{port}"}
    return overlay


class Viewer:
    """Subscribes to every channel advertised and reads everything, counting images: in a
    process of its own (`python -m oricf.bench.gateway_view URL`), so that the benchmark's
    camera and this viewer do not share one interpreter and make it a slow viewer."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.images = 0
        self.first_s = self.last_s = 0.0
        self._stop = threading.Event()
        self._topics: dict[int, str] = {}

    @property
    def images_per_s(self) -> float:
        return (self.images - 1) / (self.last_s - self.first_s) if self.images > 1 else 0.0

    def watch(self) -> None:
        from websockets.exceptions import ConnectionClosed
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        with connect(self.url, subprotocols=[Subprotocol("foxglove.sdk.v1")],
                     max_size=None) as viewer:
            while not self._stop.is_set():
                try:
                    message = viewer.recv(timeout=0.2)
                except TimeoutError:
                    continue
                except ConnectionClosed:
                    return
                if isinstance(message, str):
                    self._subscribe(viewer, json.loads(message))
                elif message[:1] == b"\x01":
                    channel = int.from_bytes(message[1:5], "little")
                    if self._topics.get(channel, "").endswith("/image"):
                        self._count_image()

    def _count_image(self) -> None:
        self.last_s = time.monotonic()
        if not self.images:
            self.first_s = self.last_s
        self.images += 1

    def _subscribe(self, viewer: Any, message: dict[str, Any]) -> None:
        if message.get("op") != "advertise":
            return
        new = [c for c in message["channels"] if c["id"] not in self._topics]
        self._topics.update({c["id"]: c["topic"] for c in new})
        viewer.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": c["id"], "channelId": c["id"]} for c in new]}))

    def stop(self) -> None:
        self._stop.set()


def start_viewer(url: str) -> subprocess.Popen[str]:
    """A viewer process (this module's main) watching the live view at url."""
    return subprocess.Popen([sys.executable, "-m", "oricf.bench.gateway_view", url],
                            stdout=subprocess.PIPE, text=True)


def stop_viewer(viewer: subprocess.Popen[str]) -> float:
    """Stops a viewer process; the images per second it received (0 if it had ended)."""
    viewer.send_signal(signal.SIGTERM)
    out, _ = viewer.communicate(timeout=30)
    try:
        return float(out.split()[-1])
    except (IndexError, ValueError):
        return 0.0


@contextmanager
def watching(port: int) -> Iterator[list[float]]:
    """A viewer process watching until the block ends; then its images per second are in
    the list yielded."""
    viewer = start_viewer(f"ws://127.0.0.1:{port}")
    rate: list[float] = []
    try:
        yield rate
    finally:
        rate.append(stop_viewer(viewer))


def main() -> int:
    """The viewer process: watches until SIGTERM, then prints its images per second."""
    viewer = Viewer(sys.argv[1])
    signal.signal(signal.SIGTERM, lambda *_: viewer.stop())
    viewer.watch()
    print(f"{viewer.images_per_s:.2f}")
    return 0


def view_table(result: InputResult, fps: float) -> None:
    cpu = result.cpu
    none = cpu["gw raw 1"]
    rows = [["no live view", f"{none * 1e3:.2f}", "1.00", "-"],
            ["live view, nobody watching", f"{cpu['gw view idle'] * 1e3:.2f}",
             f"{cpu['gw view idle'] / none:.2f}", "-"],
            ["live view, one viewer of every channel", f"{cpu['gw view'] * 1e3:.2f}",
             f"{cpu['gw view'] / none:.2f}", f"{result.view_images_per_s:.1f}"]]
    print_table(f"The live view per processed frame, {result.kind} input at {fps:g} fps, "
                f"onboard (gateway CPU from the CPU phase; frames capped at "
                f"{LiveViewConfig().max_fps:g}/s, raw ones JPEG quality "
                f"{LiveViewConfig().jpeg_quality})",
                ["people route", "gateway CPU ms", "ratio", "images/s received"], rows)


if __name__ == "__main__":
    raise SystemExit(main())
