"""scripts/ros-source.sh, the set-up's choice of ROS 2, run for real in a faked machine:
the Python it finds is a small script in a temporary folder on PATH (or PYTHON), a sourced
ROS 2 is ROS_DISTRO and an importable rclpy, the architecture is ORICF_ARCH. And
scripts/setup.sh itself, stopping with a message before it installs anything in a case it
cannot handle."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT

SCRIPTS = REPO_ROOT / "scripts"
BASH = shutil.which("bash") or "/bin/bash"


def fake_python(folder: Path, name: str, answer: str) -> Path:
    """A `python` that answers ros-source.sh's probe with `answer` (`3.9 0`: Python 3.9,
    no rclpy), as a Python of another version would."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(f"#!/bin/sh\necho '{answer}'\n")
    path.chmod(0o755)
    return path


def python_with_rclpy(folder: Path, loads: bool = True) -> Path:
    """This Python, seeing an `rclpy` package as a sourced ROS 2's PYTHONPATH shows one;
    with loads=False, one whose C extension does not load, as another Python's would not."""
    (folder / "ros" / "rclpy").mkdir(parents=True)
    (folder / "ros" / "rclpy" / "__init__.py").write_text(
        "" if loads else "raise ImportError('No module named rclpy._rclpy_pybind11')\n")
    path = folder / "bin" / "python3"
    path.parent.mkdir(parents=True)
    path.write_text(f'#!/bin/sh\nPYTHONPATH="{folder / "ros"}" exec "{sys.executable}" "$@"\n')
    path.chmod(0o755)
    return path


def run(script: str, env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    base = {k: v for k, v in os.environ.items()
            if k not in ("ROS_DISTRO", "ORICF_ROS_DISTRO", "PYTHON", "ORICF_ARCH", "ORICF_VENV")}
    return subprocess.run([BASH, str(SCRIPTS / script), *args], capture_output=True, text=True,
                          timeout=120, env={**base, **env}, cwd=REPO_ROOT, check=False)


def decide(**env: str) -> list[str]:
    """ros-source.sh's decision line, split: source, Python, extra (and the Python's
    version, left out); asserts it succeeded."""
    result = run("ros-source.sh", {"ORICF_ARCH": "x86_64", **env})
    assert result.returncode == 0, result.stderr
    return result.stdout.splitlines()[0].split()[:3]


def refused(**env: str) -> str:
    """ros-source.sh's message for a case it refuses; asserts one line and no traceback."""
    result = run("ros-source.sh", {"ORICF_ARCH": "x86_64", **env})
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.startswith("setup: ") and result.stderr.count("\n") == 1
    assert "Traceback" not in result.stderr
    return result.stderr


@pytest.mark.parametrize(("distro", "extra"), [("", "ros"), ("jazzy", "ros"),
                                               ("kilted", "ros-kilted")])
def test_the_wheels_of_the_distribution_on_x86_64(distro: str, extra: str) -> None:
    assert decide(ORICF_ROS_DISTRO=distro, PYTHON=sys.executable) == ["wheels", sys.executable,
                                                                     extra]


@pytest.mark.parametrize(("arch", "version"), [("aarch64", "3.12"), ("x86_64", "3.15")])
def test_no_wheels_for_the_machine_installs_without_ros(tmp_path: Path, arch: str,
                                                        version: str) -> None:
    python = fake_python(tmp_path, "python3", f"{version} 0")
    result = run("ros-source.sh", {"ORICF_ARCH": arch, "PYTHON": str(python)})
    decision, note = result.stdout.splitlines()
    assert result.returncode == 0 and decision.split() == ["none", str(python), "-", version]
    assert "without ROS" in note and "oricf gateway --config people_video" in note


def test_a_sourced_ros_uses_its_own_rclpy(tmp_path: Path) -> None:
    python = python_with_rclpy(tmp_path)
    result = run("ros-source.sh", {"ROS_DISTRO": "humble",
                                   "PATH": f"{python.parent}:/usr/bin:/bin"})
    decision, note = result.stdout.splitlines()
    assert decision.split() == ["system", str(python), "-",
                                f"{sys.version_info.major}.{sys.version_info.minor}"]
    assert "--system-site-packages" in note and "no ROS wheels" in note


def test_the_python_found_on_path(tmp_path: Path) -> None:
    """python3.11 where there is one and no ROS is sourced; a sourced ROS's python3."""
    fake_python(tmp_path, "python3", "3.12 1")
    fake_python(tmp_path, "python3.11", "3.11 0")
    path = {"PATH": str(tmp_path)}
    assert decide(**path)[:2] == ["wheels", str(tmp_path / "python3.11")]
    assert decide(ROS_DISTRO="jazzy", **path)[:2] == ["system", str(tmp_path / "python3")]


def test_a_python_too_old_is_refused(tmp_path: Path) -> None:
    assert "Python 3.9" in refused(PYTHON=str(fake_python(tmp_path, "python3", "3.9 0")))
    message = refused(ROS_DISTRO="foxy", PYTHON=str(fake_python(tmp_path, "py", "3.8 1")))
    assert "ROS 2 foxy runs on Python 3.8" in message and "3.10 or newer" in message


def test_a_python_that_does_not_run_is_refused(tmp_path: Path) -> None:
    broken = tmp_path / "python3"
    broken.write_text("#!/bin/sh\nexit 3\n")
    broken.chmod(0o755)
    assert "does not run: set PYTHON" in refused(PYTHON=str(broken))


def test_an_unknown_distribution_is_refused() -> None:
    message = refused(ORICF_ROS_DISTRO="humble", PYTHON=sys.executable)
    assert "ORICF_ROS_DISTRO=humble" in message and "jazzy kilted" in message
    assert "source its setup.bash" in message


def test_a_sourced_ros_without_rclpy_is_refused(tmp_path: Path) -> None:
    message = refused(ROS_DISTRO="jazzy", PYTHON=str(fake_python(tmp_path, "python3", "3.12 0")))
    assert "cannot import rclpy" in message and "source /opt/ros/jazzy/setup.bash" in message


def test_a_sourced_ros_built_for_another_python_is_refused(tmp_path: Path) -> None:
    message = refused(ROS_DISTRO="humble", PYTHON=str(python_with_rclpy(tmp_path, loads=False)))
    assert "cannot import rclpy" in message


def test_a_sourced_ros_other_than_the_one_asked_for_is_refused() -> None:
    message = refused(ROS_DISTRO="humble", ORICF_ROS_DISTRO="kilted", PYTHON=sys.executable)
    assert "humble is sourced but ORICF_ROS_DISTRO=kilted" in message
    assert "unset ORICF_ROS_DISTRO" in message


def test_setup_stops_before_installing_anything(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    result = run("setup.sh", {"ORICF_ROS_DISTRO": "rolling", "ORICF_VENV": str(venv)})
    assert result.returncode == 1 and "ORICF_ROS_DISTRO=rolling" in result.stderr
    assert "system packages" not in result.stdout and not venv.exists()


def test_setup_refuses_the_test_tools_on_python_3_10(tmp_path: Path) -> None:
    """The README's set-up runs on Python 3.10 (Ubuntu 22.04, JetPack 6); --dev does not."""
    python = fake_python(tmp_path, "python3", "3.10 0")
    result = run("setup.sh", {"PYTHON": str(python), "ORICF_VENV": str(tmp_path / "venv")},
                 "--dev")
    assert result.returncode == 1 and "need Python 3.11 or newer, not 3.10" in result.stderr
    assert "system packages" not in result.stdout and not (tmp_path / "venv").exists()


def make_venv(path: Path) -> Path:
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(path)], check=True)
    return next(path.glob("lib/python3*/site-packages"))


def test_setup_refuses_an_environment_of_another_distribution(tmp_path: Path) -> None:
    """Kilted's wheels over Jazzy's would mix two ROS 2 in one environment."""
    site = make_venv(tmp_path / "venv")
    info = site / "ros_jazzy_rclpy-7.1.6.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ros-jazzy-rclpy\nVersion: 7.1.6\n")
    result = run("setup.sh", {"ORICF_ROS_DISTRO": "kilted", "ORICF_VENV": str(tmp_path / "venv"),
                              "PYTHON": sys.executable})
    assert result.returncode == 1, result.stdout[-2000:]
    assert "holds ROS 2 jazzy's wheels" in result.stderr and "ORICF_VENV" in result.stderr


def test_setup_refuses_an_environment_blind_to_the_sourced_ros(tmp_path: Path) -> None:
    make_venv(tmp_path / "venv")   # made before ROS 2 was sourced: no rclpy in it
    python = python_with_rclpy(tmp_path / "ros")
    result = run("setup.sh", {"ROS_DISTRO": "jazzy", "PYTHON": str(python),
                              "ORICF_VENV": str(tmp_path / "venv")})
    assert result.returncode == 1, result.stdout[-2000:]
    assert "cannot import the sourced ROS 2's rclpy" in result.stderr
    assert f"rm -rf {tmp_path / 'venv'}" in result.stderr


def test_the_set_up_scripts_pass_shellcheck() -> None:
    assert shutil.which("shellcheck"), "shellcheck is missing: scripts/setup.sh --dev installs it"
    scripts = [str(SCRIPTS / name) for name in ("setup.sh", "ros-source.sh", "llama-wheel.sh",
                                                "test.sh")]
    result = subprocess.run(["shellcheck", "-x", *scripts], capture_output=True, text=True,
                            check=False, cwd=REPO_ROOT)
    assert result.returncode == 0, result.stdout
