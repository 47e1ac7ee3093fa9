"""compose/smoke-test.sh on each engine, in the engines suite (`-m engines`, docs/testing.md):
the edge image built, the stack started through compose/stack.sh, every service (the
control policy's included) SERVING through its container's health check, each answering
correctly over mTLS with the token and refusing callers without credentials, and torn down
with no container left. On Docker that is Docker's compose (v2, else v1 as Debian ships it)
and BuildKit; on podman, podman-compose.
An engine that is not installed fails the test, naming what to install."""

from __future__ import annotations

import os
import subprocess

import pytest

from oricf.config import REPO_ROOT

pytestmark = pytest.mark.engines


@pytest.mark.parametrize("engine", ["docker", "podman"])
def test_the_edge_stack_passes_the_smoke_test(engine: str) -> None:
    result = subprocess.run([str(REPO_ROOT / "compose" / "smoke-test.sh")], cwd=REPO_ROOT,
                            capture_output=True, text=True, timeout=1800, check=False,
                            env={**os.environ, "ORICF_ENGINE": engine})
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-6000:]
    assert f"engine:          {engine} (" in result.stdout
    for service in ("detector", "asr", "llm", "tts", "policy"):
        assert f"{service} SERVING after" in result.stdout  # its container's health check
        assert f"ok   {service}: " in result.stdout
        assert f"ok   {service} refuses: no token" in result.stdout
    assert "down, no container left" in result.stdout
    assert "PASS: edge stack built" in result.stdout
