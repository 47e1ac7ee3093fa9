"""Viewers for the tests: the Foxglove protocol's own client (npm @foxglove/ws-protocol, run
by Node.js; scripts/setup.sh --dev installs it) and a minimal Python one on `websockets`."""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.gateway.live_view.support import Decoder

CLIENT = Path(__file__).with_name("foxglove_client.js")


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


def official_client(url: str, seconds: float, token: str | None = None,
                    ca: Path | None = None) -> Received:
    """Runs foxglove_client.js for `seconds`; a TLS server's CA is handed to Node."""
    env = {**os.environ, "NODE_PATH": str(node_modules())}
    if ca is not None:
        env["NODE_EXTRA_CA_CERTS"] = str(ca)
    result = subprocess.run(["node", str(CLIENT), url, str(seconds), *([token] if token else [])],
                            capture_output=True, text=True, timeout=seconds + 60, env=env,
                            check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    return Received([json.loads(line) for line in result.stdout.splitlines()])
