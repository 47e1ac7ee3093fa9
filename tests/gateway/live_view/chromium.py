"""Headless Chromium (Debian's `chromium` package) driven over the Chrome DevTools Protocol
with the `websockets` client: open a page, read its DOM with JavaScript, take screenshots,
and keep what the page wrote to its console. WebGL runs on SwiftShader (no GPU needed)."""

from __future__ import annotations

import base64
import itertools
import json
import logging
import shutil
import subprocess
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import ClientConnection, connect

log = logging.getLogger(__name__)

START_TIMEOUT_S = 30.0
FLAGS = ("--headless=new", "--no-sandbox", "--no-first-run", "--no-default-browser-check",
         "--disable-gpu-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--remote-debugging-port=0", "--remote-allow-origins=*", "--hide-scrollbars")


def chromium_binary() -> str:
    """Debian's Chromium; missing is a failure naming the install command."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        pytest.fail("chromium is missing: run `apt-get install -y chromium` "
                    "(or scripts/lichtblick.sh, which installs it)")
    return found


@dataclass
class Page:
    """One tab over CDP; `console` holds what the page logged (level: text)."""

    socket: ClientConnection
    console: list[str] = field(default_factory=list)
    _ids: Iterator[int] = field(default_factory=lambda: itertools.count(1))

    def call(self, method: str, timeout: float = 60, **params: Any) -> dict[str, Any]:
        """A CDP command's result; events read meanwhile are kept."""
        call_id = next(self._ids)
        self.socket.send(json.dumps({"id": call_id, "method": method, "params": params}))
        deadline = time.monotonic() + timeout
        while True:
            message = json.loads(self.socket.recv(timeout=max(deadline - time.monotonic(), 0)))
            if message.get("id") == call_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return dict(message.get("result", {}))
            self._event(message)

    def _event(self, message: dict[str, Any]) -> None:
        params = message.get("params", {})
        if message.get("method") == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", "")))
                            for a in params.get("args", []))
            self.console.append(f"{params.get('type')}: {text}")
        elif message.get("method") == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            self.console.append("exception: " + str(
                details.get("exception", {}).get("description", details.get("text"))))
        elif message.get("method") == "Log.entryAdded":
            entry = params.get("entry", {})
            self.console.append(f"{entry.get('level')}: {entry.get('text')}")

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (promises awaited)."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                           awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float,
                 holds: Callable[[Any], bool] = bool) -> Any:
        """Polls `expression` until its value `holds`; the last value, held or not."""
        deadline = time.monotonic() + timeout
        value = self.evaluate(expression)
        while not holds(value) and time.monotonic() < deadline:
            time.sleep(0.5)
            value = self.evaluate(expression)
        return value

    def screenshot(self) -> bytes:
        """The viewport as PNG bytes."""
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])


def _debugging_port(profile: Path, process: subprocess.Popen[bytes]) -> int:
    """The port Chromium chose, from the DevToolsActivePort file it writes once listening."""
    port_file = profile / "DevToolsActivePort"
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and process.poll() is None:
        if port_file.is_file() and port_file.read_text().count("\n") >= 1:
            return int(port_file.read_text().split()[0])
        time.sleep(0.1)
    pytest.fail(f"chromium did not open its debugging port (exit code {process.poll()})")


@contextmanager
def headless_page(profile: Path, width: int = 1280, height: int = 800) -> Iterator[Page]:
    """A blank tab in a headless Chromium of its own (a fresh profile in `profile`)."""
    process = subprocess.Popen(
        [chromium_binary(), *FLAGS, f"--user-data-dir={profile}",
         f"--window-size={width},{height}", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        port = _debugging_port(profile, process)
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            tab = next(t for t in json.load(r) if t["type"] == "page")
        with connect(tab["webSocketDebuggerUrl"], max_size=None) as socket:
            page = Page(socket)
            for domain in ("Page", "Runtime", "Log"):
                page.call(f"{domain}.enable")
            page.call("Emulation.setDeviceMetricsOverride", width=width, height=height,
                      deviceScaleFactor=1, mobile=False)
            yield page
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)
