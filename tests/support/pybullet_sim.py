"""pybullet's simulated robots (the `pybullet==3.2.7` of the dev extra) and the forward pass
of their trained policies in plain numpy, to check what the policy service answers.

`pybullet_envs` imports the retired `gym` package for its environment registry, spaces and
seeding; a module of those few names stands in for it (gym itself is not installed), and
the environment classes are built directly. `step()` returns gym's old four values.
"""

from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path
from typing import Any

import numpy as np

from oricf.models.mlp_source import LAYERS

__all__ = ["forward", "hopper", "reference_arrays"]


class _Box:
    def __init__(self, low: Any, high: Any, dtype: Any = np.float32) -> None:
        self.low = np.asarray(low, dtype)
        self.high = np.asarray(high, dtype)
        self.shape = self.low.shape
        self.dtype = dtype


class _Registry:
    env_specs: dict[str, Any] = {}


def _gym_stand_in() -> None:
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


def hopper(seed: int = 0) -> Any:
    """pybullet's HopperBulletEnv, headless, reset with seed: `.reset()`, `.step(action)`."""
    _gym_stand_in()
    from pybullet_envs.gym_locomotion_envs import HopperBulletEnv

    env = HopperBulletEnv()
    env.seed(seed)
    return env


def reference_arrays(env: str) -> tuple[dict[str, np.ndarray], Path]:
    """The weights of enjoy_TF_<env>_2017may.py as pybullet itself has them: its installed
    module imported (a reference independent of the converter's parser), and its file."""
    _gym_stand_in()
    module = importlib.import_module(f"pybullet_envs.examples.enjoy_TF_{env}_2017may")
    names = [name for layer in LAYERS for name in layer]
    return ({name: np.asarray(getattr(module, name), np.float32) for name in names},
            Path(module.__file__ or ""))


def forward(arrays: dict[str, np.ndarray], observation: np.ndarray) -> np.ndarray:
    """The policy's own computation (enjoy_TF_*.py's SmallReactivePolicy.act), in numpy."""
    x = np.asarray(observation, np.float32)
    for i, (w, b) in enumerate(LAYERS):
        x = x @ arrays[w] + arrays[b]
        if i < len(LAYERS) - 1:
            x = np.maximum(x, 0)
    return x
