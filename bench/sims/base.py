"""What every simulator offers the control benchmark, and `open_sim` to open one by name."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from oricf.errors import InvalidInput
from oricf.models.policy import require_finite

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """What one action did: the next observation (float64, 1-D), the reward it earned,
    whether the episode is over, and whether the task is done (metaworld; pybullet's robots
    have no success, only a return)."""

    observation: np.ndarray
    reward: float
    done: bool
    success: bool


class Sim(Protocol):
    """A simulated robot and its task, stepped at `rate_hz` one action at a time; its
    `cameras` by name (none for most), whose views `images()` gives."""

    name: str
    rate_hz: float
    state_size: int
    action_dim: int
    action_low: np.ndarray
    action_high: np.ndarray
    max_steps: int
    cameras: tuple[str, ...]

    def reset(self, seed: int) -> np.ndarray:
        """Starts an episode, the same one for the same seed: its first observation."""
        ...

    def step(self, action: np.ndarray) -> Step:
        """Applies one action (clipped to the bounds) for one control step."""
        ...

    def images(self) -> dict[str, np.ndarray]:
        """Each camera's view after the last reset or step (BGR uint8, height x width x 3),
        by name: empty for a sim without cameras."""
        ...

    def close(self) -> None: ...


def checked_action(sim: Sim, action: np.ndarray, over: bool) -> np.ndarray:
    """The action as float64 within the sim's bounds; InvalidInput for a wrong length, a
    value that is not finite, or a step after the episode ended."""
    if over:
        raise InvalidInput(f"{sim.name}: the episode is over: reset() before stepping again")
    values = np.asarray(action, np.float64).reshape(-1)
    if values.shape != (sim.action_dim,):
        raise InvalidInput(f"{sim.name}: action: {values.size} values, the sim takes "
                           f"{sim.action_dim}")
    require_finite(values, "action")
    return np.clip(values, sim.action_low, sim.action_high)
