"""Real audio devices for tests without a sound card: a PulseAudio server of the test's own
(no system daemon, no kernel module) whose null sinks' monitors are capture devices that
PortAudio opens, while paplay plays espeak-ng speech into the sinks. Also a gateway process
whose JSON lines and log lines the tests wait for."""

from __future__ import annotations

import json
import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

from bench.common import stop
from oricf.audio import encode_wav

TOOLS = ("pulseaudio", "pactl", "paplay", "espeak-ng", "sox")


class PulseServer:
    """`pulseaudio` on a socket in `folder`; env() points clients (pactl, PortAudio's ALSA
    plugin through libpulse) at it."""

    def __init__(self, folder: Path) -> None:
        missing = [tool for tool in TOOLS if shutil.which(tool) is None]
        assert not missing, f"{', '.join(missing)} missing: run scripts/setup.sh --dev"
        self.folder = folder
        self.socket = folder / "native"
        self.log = folder / "pulseaudio.log"
        # HOME and XDG_RUNTIME_DIR: the server keeps its cookie and state here, not in ~.
        home = {"HOME": str(folder), "XDG_RUNTIME_DIR": str(folder)}
        with self.log.open("w") as log:
            self.process = subprocess.Popen(
                ["pulseaudio", "--daemonize=no", "--system=false", "--exit-idle-time=-1",
                 "--use-pid-file=no", "-n", "--log-target=stderr",
                 f"--load=module-native-protocol-unix socket={self.socket} auth-anonymous=1"],
                env={**os.environ, **home}, stdout=log, stderr=log)
        deadline = time.monotonic() + 20
        while subprocess.run(["pactl", "info"], env=self.env(), capture_output=True,
                             check=False).returncode:
            assert self.process.poll() is None, self.log.read_text()
            assert time.monotonic() < deadline, f"pulseaudio not up: {self.log.read_text()}"
            time.sleep(0.1)

    def env(self) -> dict[str, str]:
        return {**os.environ, "PULSE_SERVER": f"unix:{self.socket}"}

    def pactl(self, *args: str) -> str:
        return subprocess.run(["pactl", *args], env=self.env(), capture_output=True,
                              text=True, check=True).stdout.strip()

    def add_sink(self, name: str) -> int:
        """A null sink (its monitor, NAME.monitor, is the capture device); the module id."""
        return int(self.pactl("load-module", "module-null-sink", f"sink_name={name}"))

    def remove(self, module: int) -> None:
        self.pactl("unload-module", str(module))

    def play(self, sink: str, samples: np.ndarray, rate: int = 16000) -> float:
        """Plays mono int16 samples into the sink; the time the playback started."""
        wav = self.folder / f"play-{time.monotonic_ns()}.wav"
        wav.write_bytes(encode_wav(samples, rate))
        started = time.time()
        subprocess.run(["paplay", "-d", sink, str(wav)], env=self.env(), check=True,
                       timeout=60)
        return started

    def close(self) -> None:
        stop(self.process, timeout=10)


class Gateway:
    """`python -m oricf gateway ...`: JSON lines from stdout, log lines from stderr."""

    def __init__(self, args: list[str], env: dict[str, str]) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "oricf", "gateway", *args], env=env, text=True,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.lines: queue.Queue[dict[str, Any]] = queue.Queue()
        self.log: list[str] = []
        self._log_changed = threading.Condition()
        assert self.process.stdout is not None and self.process.stderr is not None
        threading.Thread(target=self._read_json, args=(self.process.stdout,),
                         daemon=True).start()
        threading.Thread(target=self._read_log, args=(self.process.stderr,),
                         daemon=True).start()

    def _read_json(self, stream: IO[str]) -> None:
        for line in stream:
            self.lines.put(json.loads(line))

    def _read_log(self, stream: IO[str]) -> None:
        for line in stream:
            with self._log_changed:
                self.log.append(line)
                self._log_changed.notify_all()

    @property
    def stderr(self) -> str:
        return "".join(self.log)

    def wait_log(self, text: str, timeout: float, after: int = 0) -> int:
        """Waits for a log line (from line `after` on) containing text; its index."""
        deadline = time.monotonic() + timeout
        with self._log_changed:
            while True:
                found = [i for i, line in enumerate(self.log[after:], after) if text in line]
                if found:
                    return found[0]
                left = deadline - time.monotonic()
                assert left > 0 and self.process.poll() is None, \
                    f"no log line with {text!r}:\n{self.stderr}"
                self._log_changed.wait(min(left, 0.5))

    def next_line(self, route: str, timeout: float) -> dict[str, Any]:
        """The next JSON line of a route (other routes' lines are passed over)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            if line["route"] == route:
                return line
        raise AssertionError(f"no {route} line in {timeout} s:\n{self.stderr}")

    def stop(self) -> int:
        stop(self.process, timeout=30)
        return self.process.returncode


@contextmanager
def gateway(args: list[str], env: dict[str, str]) -> Iterator[Gateway]:
    running = Gateway(args, env)
    try:
        yield running
    finally:
        if running.process.poll() is None:
            running.process.kill()
            running.process.wait()
