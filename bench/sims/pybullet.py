"""pybullet's simulated robots (`pybullet==3.2.7`, the dev extra), headless, for the
trained policies that its wheel ships (configs/models/policies/).

`pybullet_envs` imports the retired `gym` package for its environment registry, spaces and
seeding; `gym_stand_in()` puts a module of those few names in its place (gym itself is not
installed), and the environment classes are built directly, without gym's registry and so
without its time limit: an episode ends when the robot falls (the env's own `done`) or
after `MAX_STEPS`, as gym's registration had it. The robots have no success, only a return.
"""

from __future__ import annotations

import importlib
import logging
import sys
import types
from typing import Any

import numpy as np

from oricf.bench.entry import need
from oricf.bench.sims.base import Step, checked_action

log = logging.getLogger(__name__)

# name -> (pybullet_envs module, environment class); the policy of each is
# configs/models/policies/<name>.yaml.
ROBOTS = {
    "hopper": ("gym_locomotion_envs", "HopperBulletEnv"),
    "ant": ("gym_locomotion_envs", "AntBulletEnv"),
    "inverted-double-pendulum": ("gym_pendulum_envs", "InvertedDoublePendulumBulletEnv"),
}
MAX_STEPS = 1000  # gym's registration of these environments
RATE_HZ = 1 / 0.0165  # every one of them steps 0.0165 s


class _Box:
    def __init__(self, low: Any, high: Any, dtype: Any = np.float32) -> None:
        self.low = np.asarray(low, dtype)
        self.high = np.asarray(high, dtype)
        self.shape = self.low.shape
        self.dtype = dtype


class _Registry:
    env_specs: dict[str, Any] = {}


def gym_stand_in() -> None:
    """The names of the old `gym` that pybullet_envs imports, as modules in sys.modules
    (a no-op when a `gym` is already importable there)."""
    if "gym" in sys.modules:
        return
    modules = {name: types.ModuleType(name) for name in (
        "gym", "gym.spaces", "gym.utils", "gym.utils.seeding", "gym.envs",
        "gym.envs.registration")}
    gym = modules["gym"]
    gym.__version__ = "0.21.0"  # type: ignore[attr-defined]
    gym.Env = type("Env", (), {"metadata": {}})  # type: ignore[attr-defined]
    modules["gym.spaces"].Box = _Box  # type: ignore[attr-defined]
    modules["gym.utils.seeding"].np_random = (  # type: ignore[attr-defined]
        lambda seed=None: (np.random.RandomState(seed), seed))
    registration = modules["gym.envs.registration"]
    registration.registry = _Registry()  # type: ignore[attr-defined]
    registration.register = lambda *args, **kwargs: None  # type: ignore[attr-defined]
    registration.make = registration.spec = None  # type: ignore[attr-defined]
    for name, module in modules.items():
        parent, _, child = name.rpartition(".")
        if parent:
            setattr(modules[parent], child, module)
        sys.modules[name] = module


def environment(name: str) -> Any:
    """A new pybullet_envs environment of the robot `name` (headless, not yet seeded):
    `.seed(n)`, `.reset()`, and `.step(action)` with gym's old four values."""
    need("pybullet", "dev", f"the pybullet simulator {name}")
    gym_stand_in()
    module, cls = ROBOTS[name]
    return getattr(importlib.import_module(f"pybullet_envs.{module}"), cls)()


class PybulletSim:
    """One of pybullet's robots as a Sim: reward per step, done when it falls or after
    MAX_STEPS; success always False."""

    rate_hz = RATE_HZ
    max_steps = MAX_STEPS
    cameras: tuple[str, ...] = ()

    def __init__(self, name: str) -> None:
        self.name = name
        self._env = environment(name)
        space = self._env.action_space
        self.action_low = np.asarray(space.low, np.float64)
        self.action_high = np.asarray(space.high, np.float64)
        self.action_dim = int(self.action_low.size)
        self.state_size = int(self._env.observation_space.shape[0])
        self._steps = 0
        self._over = True

    def reset(self, seed: int) -> np.ndarray:
        self._env.seed(seed)
        self._steps, self._over = 0, False
        return np.asarray(self._env.reset(), np.float64)

    def step(self, action: np.ndarray) -> Step:
        values = checked_action(self, action, self._over)
        observation, reward, done, _ = self._env.step(values)
        self._steps += 1
        self._over = bool(done) or self._steps >= self.max_steps
        return Step(np.asarray(observation, np.float64), float(reward), self._over, False)

    def images(self) -> dict[str, np.ndarray]:
        return {}  # no camera: the state is the whole observation

    def close(self) -> None:
        self._env.close()
