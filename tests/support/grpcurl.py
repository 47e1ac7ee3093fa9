"""The real grpcurl binary (from the model store) against a service, as a user would run it."""

from __future__ import annotations

import subprocess

from oricf.store import ModelStore


def run_grpcurl(*args: str, data: str | None = None) -> subprocess.CompletedProcess[str]:
    """grpcurl -plaintext [-d @ with data on stdin] ARGS; the finished process."""
    command = [str(ModelStore().path("grpcurl")), "-plaintext",
               *(["-d", "@"] if data is not None else []), *args]
    return subprocess.run(command, input=data, capture_output=True, text=True, timeout=60,
                          check=False)


def grpcurl(*args: str, data: str | None = None) -> str:
    """grpcurl's output; the call must succeed."""
    result = run_grpcurl(*args, data=data)
    assert result.returncode == 0, result.stderr
    return result.stdout
