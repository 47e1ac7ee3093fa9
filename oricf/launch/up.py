"""`oricf up DEPLOYMENT.yaml`: run a deployment's services and gateway as local processes.

Starts every service of the deployment (`oricf serve NAME`), waits until each is SERVING
(grpc.health.v1), checks the remote services, starts the gateway, and streams every
process's output with its name in front. Ctrl-C or SIGTERM stops them all: SIGTERM to each
process group, then SIGKILL after the deployment's stop_grace_s. A process that ends is
reported and restarted as its `restart` policy says; one that ends for good stops the
deployment (exit 1).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from oricf.launch.deployment import load_deployment
from oricf.launch.launcher import Launcher, LaunchFailed, Stopped

log = logging.getLogger(__name__)


class PrefixedOutput:
    """Writes each process's lines as `name | line`, one whole line at a time."""

    def __init__(self, width: int = 8) -> None:
        self.width = width
        self._lock = threading.Lock()

    def __call__(self, name: str, line: str) -> None:
        with self._lock:
            sys.stdout.write(f"{name:<{self.width}} | {line}\n")
            sys.stdout.flush()


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT or SIGTERM; the previous handlers come back afterwards."""
    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        log.info("%s: stopping the deployment", signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def run(path: Path) -> int:
    deployment = load_deployment(path)
    launcher = Launcher(deployment, PrefixedOutput())
    with stop_on_signals() as stop:
        try:
            launcher.start(stop)
            names = ", ".join(p.name for p in launcher.processes)
            log.info("deployment %s running (%s); Ctrl-C stops it", path.name, names)
            code = launcher.supervise(stop)
        except Stopped:
            code = 0
        except LaunchFailed as exc:
            log.error("%s", exc)
            code = 1
        finally:
            launcher.stop()
    return code


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="oricf up", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("deployment", type=Path, help="e.g. configs/deployments/local.yaml")
    args = parser.parse_args(argv)
    return run(args.deployment)
