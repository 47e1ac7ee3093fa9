"""One child process of the launcher: its own process group, its output line by line, a stop
that always ends the whole group (SIGTERM, a grace period, then SIGKILL)."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import IO

from oricf.launch.deployment import ProcessPlan
from oricf.lifeline import child_options

log = logging.getLogger(__name__)

# (process name, line without the newline)
LineSink = Callable[[str, str], None]
TAIL_LINES = 40


class PrefixedLines:
    """A LineSink that writes `name | line` to every stream, one whole line at a time."""

    def __init__(self, *streams: IO[str], width: int = 8) -> None:
        self.streams = streams
        self.width = width
        self._lock = threading.Lock()

    def __call__(self, name: str, line: str) -> None:
        text = f"{name:<{self.width}} | {line}\n"
        with self._lock:
            for stream in self.streams:
                stream.write(text)
                stream.flush()


class ManagedProcess:
    """Starts plan.argv in a new session, so signals to the launcher's terminal (Ctrl-C) do
    not reach it directly and stop() can end every process it started (no orphans); if the
    launcher dies without stopping it, it stops by itself (oricf.lifeline)."""

    def __init__(self, plan: ProcessPlan, sink: LineSink) -> None:
        self.plan = plan
        self.sink = sink
        self.restarts = 0
        self.tail: deque[str] = deque(maxlen=TAIL_LINES)
        self._popen: subprocess.Popen[bytes] | None = None
        self._pump: threading.Thread | None = None
        self._terminated = False

    @property
    def name(self) -> str:
        return self.plan.name

    @property
    def pid(self) -> int | None:
        return self._popen.pid if self._popen else None

    def start(self) -> None:
        lifeline, pass_fds = child_options()  # it stops if this process dies unannounced
        env = {**os.environ, **self.plan.env, **lifeline, "PYTHONUNBUFFERED": "1"}
        self._terminated = False
        self._popen = subprocess.Popen(
            self.plan.argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, start_new_session=True, pass_fds=pass_fds)
        self._pump = threading.Thread(target=self._read_output, args=(self._popen,),
                                      name=f"{self.name}-output", daemon=True)
        self._pump.start()
        log.info("started %s (pid %d)", self.name, self._popen.pid)

    def _read_output(self, popen: subprocess.Popen[bytes]) -> None:
        assert popen.stdout is not None
        for raw in popen.stdout:
            line = raw.decode("utf-8", "replace").rstrip("\n")
            self.tail.append(line)
            self.sink(self.name, line)
        popen.stdout.close()

    def poll(self) -> int | None:
        """The exit code once the process has ended, else None."""
        return self._popen.poll() if self._popen else None

    def alive(self) -> bool:
        return self._popen is not None and self._popen.poll() is None

    def terminate(self) -> None:
        """SIGTERM to the whole process group (the service drains and exits), once: a
        second SIGTERM during the interpreter's shutdown would kill it mid-exit."""
        if self._popen is not None and self._popen.poll() is None and not self._terminated:
            self._terminated = True
            self._signal_group(self._popen.pid, signal.SIGTERM)

    def stop(self, grace_s: float) -> int | None:
        """SIGTERM, SIGKILL after grace_s, then SIGKILL to anything left in the group.

        Returns the exit code (None if never started)."""
        popen = self._popen
        if popen is None:
            return None
        self.terminate()
        try:
            popen.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            log.warning("%s did not stop within %.0f s: SIGKILL", self.name, grace_s)
        # Always: children the process left behind die with the group.
        self._signal_group(popen.pid, signal.SIGKILL)
        code = popen.wait()
        if self._pump is not None:
            self._pump.join(timeout=2.0)
        return code

    @staticmethod
    def _signal_group(pgid: int, signum: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(pgid, signum)


def describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def wants_restart(process: ManagedProcess, code: int) -> bool:
    policy = process.plan.restart
    if policy.policy == "no" or (policy.policy == "on-failure" and code == 0):
        return False
    return process.restarts < policy.max_restarts


def restart(process: ManagedProcess) -> None:
    time.sleep(process.plan.restart.delay_s)
    process.restarts += 1
    process.start()
