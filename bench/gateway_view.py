"""The cost of the live view in `oricf bench gateway`: the onboard gateway's CPU per
processed frame with no live view, with the live view and nobody watching, and with one
viewer subscribed to every channel (a Python viewer on `websockets` in this process that
reads everything), at the view's default frame cap. With a viewer, raw camera frames are
JPEG-encoded for it (at most max_fps of them); nobody watching, frames are not encoded."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from oricf.bench.common import print_table
from oricf.bench.gateway_report import InputResult
from oricf.gateway.live_view.config import LiveViewConfig


def view_overlay(overlay: dict[str, Any], port: int) -> dict[str, Any]:
    """A benchmark gateway overlay with the live view on 127.0.0.1:port."""
    overlay["foxglove"] = {"listen": f"127.0.0.1:{port}"}
    return overlay


class Viewer:
    """Subscribes to every channel advertised and reads everything, counting images."""

    def __init__(self, port: int) -> None:
        self.url = f"ws://127.0.0.1:{port}"
        self.images = 0
        self.bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._topics: dict[int, str] = {}

    def _watch(self) -> None:
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
                    self.bytes += len(message)
                    channel = int.from_bytes(message[1:5], "little")
                    self.images += self._topics.get(channel, "").endswith("/image")

    def _subscribe(self, viewer: Any, message: dict[str, Any]) -> None:
        if message.get("op") != "advertise":
            return
        new = [c for c in message["channels"] if c["id"] not in self._topics]
        self._topics.update({c["id"]: c["topic"] for c in new})
        viewer.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": c["id"], "channelId": c["id"]} for c in new]}))

    @contextmanager
    def watching(self) -> Iterator[Viewer]:
        self._thread.start()
        try:
            yield self
        finally:
            self._stop.set()
            self._thread.join(timeout=10)


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
