"""pybullet's simulated robots (the `pybullet==3.2.7` of the dev extra, through
oricf.bench.sims.pybullet) and the forward pass of their trained policies in plain numpy, to
check what the policy service answers. `step()` returns gym's old four values.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import numpy as np

from oricf.bench.sims.pybullet import environment, gym_stand_in
from oricf.models.mlp_source import LAYERS

__all__ = ["forward", "hopper", "reference_arrays"]


def hopper(seed: int = 0) -> Any:
    """pybullet's HopperBulletEnv, headless, reset with seed: `.reset()`, `.step(action)`."""
    env = environment("hopper")
    env.seed(seed)
    return env


def reference_arrays(env: str) -> tuple[dict[str, np.ndarray], Path]:
    """The weights of enjoy_TF_<env>_2017may.py as pybullet itself has them: its installed
    module imported (a reference independent of the converter's parser), and its file."""
    gym_stand_in()
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
