"""Fixtures for gateway tests: a private DDS domain, an rclpy context, a real robot's state
(the services are the session's, tests/conftest.py)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest
from rclpy.context import Context

from tests.gateway.ros.gateway_node import private_domain
from tests.support.pybullet_sim import hopper


@pytest.fixture(scope="session")
def ros_env() -> Iterator[dict[str, str]]:
    """ROS_DOMAIN_ID / discovery range for this run, set before any rclpy.init."""
    env = private_domain()
    saved = {key: os.environ.get(key) for key in env}
    os.environ.update(env)
    yield env
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.fixture()
def ros_context(ros_env: dict[str, str]) -> Iterator[Context]:
    import rclpy

    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture(scope="module")
def hopper_state() -> np.ndarray:
    """A state of the simulated Hopper, one step after its reset (seed 0)."""
    env = hopper(seed=0)
    env.reset()
    state, *_ = env.step(np.zeros(3))
    return np.asarray(state, np.float64)

