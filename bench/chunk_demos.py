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
from typing import TypeVar

import numpy as np

from oricf.bench.sims.metaworld import MetaworldSim, expert
from oricf.errors import ConfigError

log = logging.getLogger(__name__)

T = TypeVar("T")

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


@dataclass(frozen=True)
class Demonstration:
    """One successful episode: each step's observation, the expert's clean action, and the
    action executed (the clean one with the noise, within the bounds)."""

    observations: np.ndarray  # [steps, state]
    clean: np.ndarray  # [steps, dim]
    executed: np.ndarray  # [steps, dim]


def episode(sim: MetaworldSim, act: Callable[[np.ndarray], np.ndarray], reset_seed: int,
            noise: float) -> tuple[Demonstration, bool]:
    """One demonstration, and whether it succeeded."""
    rng = np.random.default_rng(reset_seed)
    observation = sim.reset(reset_seed)
    observations, actions, executed = [], [], []
    success = False
    for _ in range(sim.max_steps):
        clean = act(observation)
        observations.append(observation)
        actions.append(clean)
        noisy = clean + rng.normal(0.0, noise, clean.shape) if noise else clean
        executed.append(np.clip(noisy, sim.action_low, sim.action_high))
        step = sim.step(executed[-1])
        observation = step.observation
        if step.done:
            success = step.success
            break
    return Demonstration(np.asarray(observations), np.asarray(actions),
                         np.asarray(executed)), success


def chunks(actions: np.ndarray, chunk: int, lead: int = 0) -> np.ndarray:
    """[steps, chunk * dim]: row t holds actions t+lead .. t+lead+chunk-1, the episode's
    last action repeated past its end."""
    last = len(actions) - 1
    index = np.minimum(np.arange(len(actions))[:, None] + lead + np.arange(chunk)[None, :],
                       last)
    return actions[index].reshape(len(actions), -1)


def successful(run: Callable[[int], tuple[T, bool]], demos: int, seed: int, tries: int,
               task: str, noise: float) -> list[T]:
    """`demos` successful demonstrations of `task`'s expert, `run(reset_seed)` trying one
    on seeds from demo_seed(seed, 0) on, at most `tries` times as many; ConfigError when
    the expert succeeds in too few."""
    kept: list[T] = []
    tried = 0
    while len(kept) < demos and tried < tries * demos:
        demo, success = run(demo_seed(seed, tried))
        tried += 1
        if success:
            kept.append(demo)
    if len(kept) < demos:
        raise ConfigError(f"{task}: the expert succeeded in {len(kept)} of {tried} episodes "
                          f"(noise {noise}): too few demonstrations")
    log.info("%s: %d demonstrations kept of %d", task, len(kept), tried)
    return kept


def demonstrations(task: str, demos: int, seed: int, noise: float) -> list[Demonstration]:
    """`demos` successful episodes of the metaworld expert (at most 3x as many tried)."""
    sim = MetaworldSim(task)
    act = expert(task)
    try:
        return successful(lambda reset_seed: episode(sim, act, reset_seed, noise), demos,
                          seed, 3, task, noise)
    finally:
        sim.close()


def collect(task: str, demos: int, seed: int, noise: float, chunk: int,
            lead: int = 0) -> Demos:
    """The observations of `demos` successful episodes, each with the expert's next chunk."""
    kept = demonstrations(task, demos, seed, noise)
    return Demos(np.concatenate([demo.observations for demo in kept]),
                 np.concatenate([chunks(demo.clean, chunk, lead) for demo in kept]))
