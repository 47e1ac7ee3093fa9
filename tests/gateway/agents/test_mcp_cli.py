"""`oricf mcp` on the command line: its help, and what it refuses before serving."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml


def oricf_mcp(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "oricf", "mcp", *args], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL)


def test_help_names_the_modes_and_tools() -> None:
    done = oricf_mcp("--help")
    assert done.returncode == 0
    for words in ("--config", "--attach", "--transport", "stdio", "streamable HTTP",
                  "list_products", "publish", "agent:", "docs/agents.md"):
        assert words in done.stdout


def test_stdout_outputs_refused_over_stdio(tmp_path: Path) -> None:
    config = tmp_path / "printing.yaml"
    config.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": "127.0.0.1:1"}},
        "routes": {"people": {"input": {"url": "video.avi"},
                              "call": {"service": "detector", "method": "Detect"},
                              "outputs": [{"jsonl": "-", "from": "detections"}]}}}))
    done = oricf_mcp("--config", str(config))
    assert done.returncode == 2
    assert "routes.people.outputs[0]: writes to standard output" in done.stderr
    assert done.stdout == ""  # standard output is the protocol's


def test_attach_needs_an_address_it_knows() -> None:
    done = oricf_mcp("--attach", "ftp://robot")
    assert done.returncode == 2 and "unix:PATH or http(s)://HOST:PORT" in done.stderr


def test_attach_to_no_gateway(tmp_path: Path) -> None:
    done = oricf_mcp("--attach", f"unix:{tmp_path / 'nobody.sock'}")
    assert done.returncode == 2 and "gateway control API at unix:" in done.stderr
    assert "Traceback" not in done.stderr
