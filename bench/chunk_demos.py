"""Demonstrations of a metaworld task by its scripted expert, as training pairs for a
chunk policy: each observation and the expert's `chunk` actions from `lead` steps after it
(lead 0: from the observation's own step on; a policy trained with a lead acts ahead of a
known round trip).

The executed action may carry Gaussian noise (DART) while the label is the expert's own
clean action; a chunk that runs past the episode's end repeats its last action (the arm
holds still at the goal). Only successful episodes are kept.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from oricf.bench.sims.metaworld import MetaworldSim, expert
from oricf.errors import ConfigError

log = logging.getLogger(__name__)

DEMO_SEEDS = 1_000_000  # episode seeds from here on are demonstrations (see below)
MIN_STD = 1e-3  # a value the demonstrations never vary (an absent second object) stays 0


@dataclass(frozen=True)
class Demos:
    observations: np.ndarray  # [steps, state]
    targets: np.ndarray  # [steps, chunk * action]: the expert's next chunk, row-major

    def normalisation(self) -> tuple[np.ndarray, np.ndarray]:
        """The observations' mean and std (floored at MIN_STD, and 1 where constant)."""
        std = self.observations.std(axis=0)
        return self.observations.mean(axis=0), np.where(std < MIN_STD, 1.0, std)


def demo_seed(seed: int, episode: int) -> int:
    """The reset seed of a demonstration episode: never below DEMO_SEEDS."""
    return DEMO_SEEDS + 1000 * seed + episode


def episode(sim: MetaworldSim, act: Callable[[np.ndarray], np.ndarray], reset_seed: int,
            noise: float) -> tuple[list[np.ndarray], list[np.ndarray], bool]:
    """One demonstration: (observations, clean expert actions, success)."""
    rng = np.random.default_rng(reset_seed)
    observation = sim.reset(reset_seed)
    observations, actions = [], []
    for _ in range(sim.max_steps):
        clean = act(observation)
        observations.append(observation)
        actions.append(clean)
        executed = clean + rng.normal(0.0, noise, clean.shape) if noise else clean
        step = sim.step(np.clip(executed, sim.action_low, sim.action_high))
        observation = step.observation
        if step.done:
            return observations, actions, step.success
    return observations, actions, False


def chunks(actions: np.ndarray, chunk: int, lead: int = 0) -> np.ndarray:
    """[steps, chunk * dim]: row t holds actions t+lead .. t+lead+chunk-1, the episode's
    last action repeated past its end."""
    last = len(actions) - 1
    index = np.minimum(np.arange(len(actions))[:, None] + lead + np.arange(chunk)[None, :],
                       last)
    return actions[index].reshape(len(actions), -1)


def collect(task: str, demos: int, seed: int, noise: float, chunk: int,
            lead: int = 0) -> Demos:
    """`demos` successful episodes of the expert (at most 3x as many tried)."""
    sim = MetaworldSim(task)
    act = expert(task)
    observations, targets, kept, tried = [], [], 0, 0
    try:
        while kept < demos and tried < 3 * demos:
            obs, actions, success = episode(sim, act, demo_seed(seed, tried), noise)
            tried += 1
            if success:
                kept += 1
                observations.append(np.asarray(obs))
                targets.append(chunks(np.asarray(actions), chunk, lead))
    finally:
        sim.close()
    if kept < demos:
        raise ConfigError(f"{task}: the expert succeeded in {kept} of {tried} episodes "
                          f"(noise {noise}): too few demonstrations")
    log.info("%s: %d demonstrations kept of %d", task, kept, tried)
    return Demos(np.concatenate(observations), np.concatenate(targets))
