"""Viewers for the tests: the Foxglove protocol's own client (npm @foxglove/ws-protocol, run
by Node.js; scripts/setup.sh --dev installs it) and a minimal Python one on `websockets`."""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from websockets.sync.client import connect
from websockets.typing import Subprotocol

from tests.gateway.live_view.support import Decoder, message_data, subscribe_all

CLIENT = Path(__file__).with_name("foxglove_client.js")
PUBLISHER = Path(__file__).with_name("foxglove_publisher.js")


def node_modules() -> Path:
    """Where setup.sh --dev installed @foxglove/ws-protocol; missing is a failure, not a
    skip."""
    folder = Path(os.environ.get("ORICF_NODE_MODULES") or Path(
        os.environ.get("ORICF_CACHE", Path.home() / ".cache" / "oricf")) / "node"
        / "node_modules")
    package = folder / "@foxglove" / "ws-protocol" / "package.json"
    assert shutil.which("node"), "node is missing: run scripts/setup.sh --dev"
    assert package.is_file(), f"{package} is missing: run scripts/setup.sh --dev"
    assert json.loads(package.read_text())["version"] == "0.8.0"
    return folder


@dataclass
class Received:
    """What the official client printed: channels advertised, messages decoded by topic."""

    lines: list[dict[str, Any]]
    decoder: Decoder = field(default_factory=Decoder)
    messages: dict[str, list[tuple[int, Any]]] = field(default_factory=dict)  # (ns, message)

    def __post_init__(self) -> None:
        for line in self.lines:
            if "advertise" in line:
                self.decoder.advertise(line["advertise"])
            elif "message" in line:
                m = line["message"]
                topic, message = self.decoder.decode(m["channelId"],
                                                     base64.b64decode(m["data"]))
                self.messages.setdefault(topic, []).append((int(m["logTime"]), message))

    @property
    def topics(self) -> dict[str, str]:
        return {c["topic"]: c["schemaName"] for c in self.decoder.channels.values()}


def client_command(url: str, seconds: float, token: str | None = None,
                   ca: Path | None = None) -> tuple[list[str], dict[str, str]]:
    env = {**os.environ, "NODE_PATH": str(node_modules())}
    if ca is not None:  # a TLS server's CA
        env["NODE_EXTRA_CA_CERTS"] = str(ca)
    return ["node", str(CLIENT), url, str(seconds), *([token] if token else [])], env


def official_client(url: str, seconds: float, token: str | None = None,
                    ca: Path | None = None) -> Received:
    """Runs foxglove_client.js for `seconds`."""
    command, env = client_command(url, seconds, token, ca)
    result = subprocess.run(command, capture_output=True, text=True, timeout=seconds + 60,
                            env=env, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    return Received([json.loads(line) for line in result.stdout.splitlines()])


def publishing_client(url: str, count: int, seconds: float) -> Received:
    """Runs foxglove_publisher.js: `count` messages on channels of its own it never
    advertised, then watching every channel until a message comes (`seconds` at most)."""
    env = {**os.environ, "NODE_PATH": str(node_modules())}
    result = subprocess.run(["node", str(PUBLISHER), url, str(count), str(seconds)],
                            capture_output=True, text=True, timeout=seconds + 60, env=env,
                            check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    return Received([json.loads(line) for line in result.stdout.splitlines()])


@contextmanager
def watching(url: str, early: bool = False) -> Iterator[list[Received]]:
    """foxglove_client.js watching until the block ends; then what it received is in the
    list yielded. Its output goes to a file: a pipe nobody reads until the end would fill
    and make it a slow viewer, which the server rightly drops messages for. `early`: started
    before the server listens, it connects (and subscribes) the moment the server does."""
    command, env = client_command(url, 3600)
    if early:
        env["FOXGLOVE_CLIENT_RETRY"] = "1"
    got: list[Received] = []
    with tempfile.TemporaryFile("w+") as out:
        client = subprocess.Popen(command, stdout=out, stderr=subprocess.PIPE, text=True,
                                  env=env)
        try:
            yield got
        finally:
            client.terminate()
            _, err = client.communicate(timeout=30)
        assert client.returncode == 0, err[-2000:]
        out.seek(0)
        lines = out.read().splitlines()
    got.append(Received([json.loads(line) for line in lines]))


@contextmanager
def stalled_viewer(url: str, topic: str) -> Iterator[None]:
    """A Python viewer that subscribes to every channel once `topic` is advertised, then
    never reads again until the block ends (its client holds one message, then stops reading
    the socket)."""
    decoder = Decoder()
    with connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")], max_queue=1) as stalled:
        stalled.recv(timeout=5)  # serverInfo
        while not any(c["topic"] == topic for c in decoder.channels.values()):
            decoder.advertise(json.loads(stalled.recv(timeout=10))["channels"])
        stalled.send(subscribe_all(decoder))
        yield


def watch_images(url: str, seconds: float, topic: str = "/people/image",
                 until: Callable[[list[int]], bool] | None = None) -> list[int]:
    """A Python viewer that reads everything for `seconds`, or until `until` holds for what
    it got so far, subscribed to `topic`: the size of each message it got there."""
    decoder, sizes = Decoder(), list[int]()
    with connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")]) as viewer:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and not (until is not None and until(sizes)):
            try:
                frame = viewer.recv(timeout=0.5)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "advertise":
                    decoder.advertise(message["channels"])
                    viewer.send(subscribe_all(decoder, {topic}))
                continue
            channel, _, payload = message_data(frame)
            if decoder.channels[channel]["topic"] == topic:
                sizes.append(len(payload))
    return sizes


def watch(url: str, seconds: float, enough: Callable[[int], bool] | None = None) -> int:
    """The images of /people/image a viewer that reads everything gets in `seconds`, or by
    the time `enough` holds for their number."""
    until = None if enough is None else (lambda sizes: enough(len(sizes)))
    return len(watch_images(url, seconds, until=until))
