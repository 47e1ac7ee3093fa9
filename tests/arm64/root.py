"""The emulated arm64 root (scripts/arm64-root.sh): set up once a session, and ORICF's own
commands run in it as processes of this machine's network, so a service there answers a
client here on 127.0.0.1."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT
from oricf.launch.health import free_port, wait_serving

ROOT_SCRIPT = REPO_ROOT / "scripts" / "arm64-root.sh"
SETUP_SCRIPT = REPO_ROOT / "scripts" / "arm64-setup.sh"
ORICF = "/opt/oricf/venv/bin/oricf"       # the root's own ORICF (scripts/arm64-setup.sh)
# Under emulation a model loads 10-50 times slower than here: a service may take minutes.
SERVING_TIMEOUT_S = 900.0
SETUP_TIMEOUT_S = 3 * 3600.0   # a first run: the root, the Arm wheel and every package
TOOLS = {"debootstrap": "debootstrap", "qemu-aarch64-static": "qemu-user-static",
         "update-binfmts": "binfmt-support", "aarch64-linux-gnu-g++": "g++-aarch64-linux-gnu",
         "cmake": "cmake", "unshare": "util-linux"}


def require_tools() -> None:
    """Fails, naming what to install, where the root cannot be made or entered."""
    if os.geteuid() != 0:
        pytest.fail("the arm64 suite needs root (debootstrap, chroot, mounts)")
    missing = sorted({package for tool, package in TOOLS.items() if not shutil.which(tool)})
    if missing:
        pytest.fail(f"the arm64 suite needs: apt-get install -y {' '.join(missing)}")


def set_up() -> str:
    """scripts/arm64-setup.sh: its output, with how long each step took."""
    require_tools()
    result = subprocess.run([str(SETUP_SCRIPT)], capture_output=True, text=True,
                            timeout=SETUP_TIMEOUT_S)
    if result.returncode != 0:
        pytest.fail(f"scripts/arm64-setup.sh failed ({result.returncode}):\n"
                    f"{result.stdout[-4000:]}\n{result.stderr[-4000:]}")
    return result.stdout


def run_in_root(*command: str, timeout: float = 600.0) -> str:
    """COMMAND in the root, to its end; its standard output (fails the test on an error)."""
    result = subprocess.run([str(ROOT_SCRIPT), "run", *command], capture_output=True,
                            text=True, timeout=timeout)
    assert result.returncode == 0, f"{command} in the root: {result.stderr[-3000:]}"
    return result.stdout


@contextmanager
def root_process(*command: str, stdout: bool = False) -> Iterator[subprocess.Popen[str]]:
    """COMMAND started in the root in a process group of its own, killed on exit. Its log
    goes to a file (a pipe nobody reads would stop it once full) and with a failure; its
    standard output to `process.stdout` when `stdout`, else to that file too."""
    with tempfile.TemporaryFile("w+") as log:
        process = subprocess.Popen([str(ROOT_SCRIPT), "run", *command], text=True,
                                   stdout=subprocess.PIPE if stdout else log, stderr=log,
                                   start_new_session=True)
        try:
            yield process
        except BaseException:
            stop(process)
            log.seek(0)
            print(f"{command} in the arm64 root:\n{log.read()[-20000:]}", file=sys.stderr)
            raise
        finally:
            stop(process)


def stop(process: subprocess.Popen[str]) -> None:
    """SIGTERM (a service drains), then SIGKILL for what is left after a minute."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)


@contextmanager
def service_in_root(name: str) -> Iterator[str]:
    """`oricf serve NAME` in the root on a free port; its address once it is SERVING."""
    address = f"127.0.0.1:{free_port()}"
    with root_process(ORICF, "serve", name, "--listen", address) as process:
        started = time.monotonic()
        wait_serving(address, timeout=SERVING_TIMEOUT_S, process=process)
        print(f"arm64 {name}: SERVING after {time.monotonic() - started:.0f} s")
        yield address


def root_path(path: str) -> Path:
    """Where a path of the root lies on this machine."""
    root = subprocess.run([str(ROOT_SCRIPT), "path"], capture_output=True, text=True,
                          check=True).stdout.strip()
    return Path(root) / path.lstrip("/")
