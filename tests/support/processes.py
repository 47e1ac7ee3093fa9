"""Real `oricf` processes for tests: free ports, readiness, no orphans."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

from oricf.launch.health import free_port, wait_serving

__all__ = ["free_port", "oricf_process", "wait_serving"]


@contextmanager
def oricf_process(*args: str, env: dict[str, str] | None = None
                  ) -> Iterator[subprocess.Popen[str]]:
    """`python -m oricf ARGS` in its own process group, killed on exit whatever happens."""
    process = subprocess.Popen(
        [sys.executable, "-m", "oricf", *args], env={**os.environ, **(env or {})},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        yield process
    except BaseException:
        # A service that exited on its own said why: its output goes with the failure.
        if process.poll() is not None and process.stdout:
            print(f"`oricf {' '.join(args)}` exited with {process.returncode}:\n"
                  f"{process.stdout.read()}", file=sys.stderr)
        raise
    finally:
        if process.poll() is None:
            os.killpg(process.pid, 9)
        process.wait(timeout=10)
        if process.stdout:
            process.stdout.close()
