"""The ROS 2 the tests run on is the distribution asked for: ORICF_ROS_DISTRO (jazzy unless
set; `ORICF_ROS_DISTRO=kilted scripts/test.sh` for Kilted, docs/testing.md), from its PyPI
wheels, or a sourced install's (ROS_DISTRO). So a run said to be on Kilted is on Kilted."""

from __future__ import annotations

import importlib.metadata
import os
from pathlib import Path

import rclpy


def test_rclpy_is_the_asked_for_distribution_s() -> None:
    asked = os.environ.get("ORICF_ROS_DISTRO") or os.environ.get("ROS_DISTRO") or "jazzy"
    if os.environ.get("ROS_DISTRO"):  # a sourced install: its rclpy, under /opt/ros/DISTRO
        assert os.environ["ROS_DISTRO"] == asked
        assert f"/{asked}/" in Path(rclpy.__file__).as_posix()
        return
    wheel = f"ros-{asked}-rclpy"
    try:
        rclpy_version = importlib.metadata.version(wheel)
    except importlib.metadata.PackageNotFoundError:
        raise AssertionError(f"{wheel} is not installed here: run ORICF_ROS_DISTRO={asked} "
                             f"scripts/setup.sh --dev (ORICF_VENV=.venv-{asked})") from None
    assert importlib.metadata.version("ros-rclpy") == rclpy_version
    others = {f"ros-{d}-rclpy" for d in ("jazzy", "kilted") if d != asked}
    installed = {d.metadata["Name"].lower() for d in importlib.metadata.distributions()}
    assert not others & installed, f"two distributions' wheels in one environment: {others}"
