"""Real `oricf` processes for tests: free ports, readiness, no orphans."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from oricf.launch.health import free_port, wait_serving

__all__ = ["free_port", "oricf_process", "wait_serving"]


# Its sitecustomize makes SIGUSR1 dump every thread's stack.
STACK_DUMPS = Path(__file__).parent / "stack_dumps"
DUMP_WAIT_S = 1.0


@contextmanager
def oricf_process(*args: str, env: dict[str, str] | None = None
                  ) -> Iterator[subprocess.Popen[str]]:
    """`python -m oricf ARGS` in its own process group, killed on exit whatever happens.

    When the test fails, the process's output goes with the failure: a process that exited
    on its own said why, and one still running (hung in a stop, say) first writes where each
    of its threads stands."""
    env = {**os.environ, **(env or {})}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(STACK_DUMPS),
                                                      env.get("PYTHONPATH")]))
    process = subprocess.Popen(
        [sys.executable, "-m", "oricf", *args], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        yield process
    except BaseException:
        if process.stdout:
            state = f"exited with {process.poll()}"
            if process.returncode is None:
                process.send_signal(signal.SIGUSR1)
                time.sleep(DUMP_WAIT_S)
                os.killpg(process.pid, signal.SIGKILL)
                process.wait(timeout=10)
                state = "was still running (its threads' stacks below; then killed)"
            print(f"`oricf {' '.join(args)}` {state}:\n{process.stdout.read()}",
                  file=sys.stderr)
        raise
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=10)
        if process.stdout:
            process.stdout.close()
