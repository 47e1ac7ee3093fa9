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
import sys
from pathlib import Path

from oricf.launch.deployment import load_deployment
from oricf.launch.launcher import Launcher, LaunchFailed, Stopped
from oricf.launch.process import PrefixedLines
from oricf.signals import stop_on_signals

log = logging.getLogger(__name__)


def run(path: Path) -> int:
    deployment = load_deployment(path)
    launcher = Launcher(deployment, PrefixedLines(sys.stdout))
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
