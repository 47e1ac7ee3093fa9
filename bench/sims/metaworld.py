"""metaworld's v3 arm tasks (`metaworld==3.1.1` on MuJoCo, the dev extra) and their
scripted experts, headless (nothing is rendered).

Each task is `gym.make("Meta-World/MT1", env_name=NAME)`: a 39-value observation (the
hand, the gripper, the objects, the previous frame's of both, the goal), a 4-value action in
[-1, 1] (the hand's motion and the gripper), 80 steps a second (MuJoCo's 2.5 ms x 5).
MT1 picks the object and goal positions out of 50 drawn once; here `reset(seed)` draws them
afresh from the task's own range with the env's generator seeded by `seed`, as metaworld
does when it makes those 50, so every seed is its own episode and no seed repeats
another's. An episode ends at its first success or after the env's limit (500 steps).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np

from oricf.bench.entry import missing, need
from oricf.bench.sims.base import Step, checked_action
from oricf.errors import ConfigError

log = logging.getLogger(__name__)

RATE_HZ = 80.0  # frame_skip 5 x MuJoCo's timestep 2.5 ms


@cache
def task_names() -> tuple[str, ...]:
    """The v3 tasks metaworld has (none when it is not installed)."""
    if missing("metaworld", "dev") is not None:
        return ()
    import metaworld

    return tuple(sorted(metaworld.ALL_V3_ENVIRONMENTS))


def _make(name: str) -> Any:
    """MT1's env for the task, its positions drawn afresh at each reset."""
    need("metaworld", "dev", f"the metaworld task {name}")
    import gymnasium as gym
    import metaworld  # noqa: F401  (registers the Meta-World/ environments)

    if name not in task_names():
        raise ConfigError(f"no metaworld v3 task {name!r}")
    env = gym.make("Meta-World/MT1", env_name=name, seed=0, disable_env_checker=True)
    env.reset()  # MT1 sets one of its tasks: the task's mode (its goal observed)
    env.get_wrapper_attr("toggle_sample_tasks_on_reset")(False)
    arm: Any = env.unwrapped
    # Positions drawn at each reset from the env's own generator (seeded in reset()),
    # instead of MT1's 50 fixed ones: metaworld's own way of making those 50.
    arm._freeze_rand_vec = False
    arm.seeded_rand_vec = True
    return env


class MetaworldSim:
    """A metaworld v3 task as a Sim: success from the env's `info["success"]`."""

    rate_hz = RATE_HZ
    state_size = 39
    action_dim = 4
    cameras: tuple[str, ...] = ()

    def __init__(self, name: str) -> None:
        self.name = name
        self._env = _make(name)
        self.max_steps = int(self._env.spec.max_episode_steps or self._env.unwrapped
                             .max_path_length)
        space = self._env.action_space
        self.action_low = np.asarray(space.low, np.float64)
        self.action_high = np.asarray(space.high, np.float64)
        self._over = True

    def reset(self, seed: int) -> np.ndarray:
        self._env.unwrapped.seed(seed)
        observation, _ = self._env.reset()
        self._over = False
        return np.asarray(observation, np.float64)

    def step(self, action: np.ndarray) -> Step:
        values = checked_action(self, action, self._over)
        observation, reward, terminated, truncated, info = self._env.step(values)
        success = bool(info.get("success", False))
        self._over = success or bool(terminated) or bool(truncated)
        return Step(np.asarray(observation, np.float64), float(reward), self._over, success)

    def images(self) -> dict[str, np.ndarray]:
        return {}  # no camera: the state is the whole observation

    def close(self) -> None:
        self._env.close()


def expert(name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The task's scripted policy (metaworld.policies): observation -> action."""
    need("metaworld", "dev", f"the metaworld expert for {name}")
    from metaworld.policies import ENV_POLICY_MAP

    if name not in ENV_POLICY_MAP:
        raise ConfigError(f"no metaworld expert for {name!r}; the tasks are "
                          f"{', '.join(sorted(ENV_POLICY_MAP))}")
    expert_class: Any = ENV_POLICY_MAP[name]  # a concrete subclass, typed as the base
    policy = expert_class()

    def act(observation: np.ndarray) -> np.ndarray:
        # The experts warn whenever a gain saturates; the env clips to [-1, 1] anyway.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.asarray(policy.get_action(observation), np.float64)
    return act
