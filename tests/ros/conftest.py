"""The ROS 2 package ros/oricf_gateway, built by colcon into a temporary workspace as on a
robot, with this environment's Python (the one that has `oricf` and rclpy)."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT
from tests.gateway.conftest import ros_context, ros_env

__all__ = ["Workspace", "ros_context", "ros_env", "workspace"]

PACKAGE = REPO_ROOT / "ros" / "oricf_gateway"


@dataclass(frozen=True)
class Workspace:
    root: Path
    build_log: str

    @property
    def install(self) -> Path:
        return self.root / "install"

    @property
    def prefix(self) -> Path:
        return self.install / "oricf_gateway"

    def env(self) -> dict[str, str]:
        """The environment after `. install/setup.sh` (AMENT_PREFIX_PATH, PYTHONPATH...)."""
        shell = subprocess.run(["sh", "-c", '. "$0/setup.sh" && env -0', str(self.install)],
                               capture_output=True, check=True)
        pairs = (item.split("=", 1) for item in shell.stdout.decode().split("\0") if item)
        return dict(pairs)


@pytest.fixture(scope="session")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """`python -m colcon build` of the package alone; fails (never skips) without colcon,
    which scripts/setup.sh --dev installs."""
    root = tmp_path_factory.mktemp("ros_ws")
    build = subprocess.run(
        [sys.executable, "-m", "colcon", "--log-base", str(root / "log"), "build",
         "--base-paths", str(PACKAGE.parent), "--build-base", str(root / "build"),
         "--install-base", str(root / "install")],
        cwd=root, capture_output=True, text=True, timeout=300,
        env={k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH",
                                                               "COLCON_PREFIX_PATH")})
    log = build.stdout + build.stderr
    assert build.returncode == 0, f"colcon build failed (scripts/setup.sh --dev installs " \
                                  f"colcon):\n{log}"
    return Workspace(root, log)
