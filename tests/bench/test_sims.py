"""The control benchmark's simulators: pybullet's robots driven by their trained policies
(loaded as `oricf serve policy` loads them), a metaworld task solved by its scripted
expert, the same episode for the same seed, and every bad call refused clearly."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from oricf.bench.sims import Sim, open_sim
from oricf.bench.sims.metaworld import expert
from oricf.config import REPO_ROOT
from oricf.errors import ConfigError, InvalidInput
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.store import ModelStore

POLICIES = REPO_ROOT / "configs" / "models" / "policies"
ROBOTS = [("hopper", 15, 3), ("ant", 28, 8), ("inverted-double-pendulum", 9, 1)]
STEPS = 200  # long enough that an untrained controller falls


@pytest.fixture(scope="module")
def pick_place() -> Iterator[Sim]:
    sim = open_sim("pick-place-v3")
    yield sim
    sim.close()


@pytest.mark.parametrize(("name", "state", "action"), ROBOTS, ids=[r[0] for r in ROBOTS])
def test_each_pybullet_robot_is_driven_by_its_trained_policy(name: str, state: int,
                                                             action: int) -> None:
    policy = PolicyModel(load_declaration(POLICIES / f"{name}.yaml"), ModelStore())
    policy.load()
    sim = open_sim(name)
    try:
        assert (sim.state_size, sim.action_dim, sim.max_steps) == (state, action, 1000)
        assert sim.rate_hz == pytest.approx(policy.task.rate_hz, rel=1e-4)
        observation = sim.reset(seed=0)
        assert observation.dtype == np.float64 and observation.shape == (state,)
        total = 0.0
        for _ in range(STEPS):
            step = sim.step(policy.act(observation)[0])
            assert not step.done and not step.success  # it stays up; robots have no success
            total += step.reward
            observation = step.observation
        assert total > 0
    finally:
        sim.close()
        policy.close()


def test_a_metaworld_task_is_solved_by_its_expert_and_ends_at_success(pick_place: Sim) -> None:
    assert (pick_place.state_size, pick_place.action_dim, pick_place.rate_hz) == (39, 4, 80.0)
    assert pick_place.max_steps == 500
    np.testing.assert_array_equal(pick_place.action_low, -np.ones(4))
    act = expert("pick-place-v3")
    observation = pick_place.reset(seed=0)
    assert observation.dtype == np.float64 and observation.shape == (39,)
    for _ in range(pick_place.max_steps):
        step = pick_place.step(act(observation))
        observation = step.observation
        if step.done:
            break
    assert step.success and step.done
    with pytest.raises(InvalidInput, match="the episode is over: reset"):
        pick_place.step(np.zeros(4))


def test_a_seed_is_one_episode_and_seeds_differ(pick_place: Sim) -> None:
    first = pick_place.reset(seed=5)
    pick_place.step(np.ones(4))
    np.testing.assert_array_equal(pick_place.reset(seed=5), first)
    assert not np.array_equal(pick_place.reset(seed=6), first)  # object and goal elsewhere


def test_an_unknown_simulator_is_refused_naming_those_there_are() -> None:
    with pytest.raises(ConfigError, match=r"no simulator 'hoper'.*hopper, ant, inverted-"
                                          r"double-pendulum.*pick-place-v3"):
        open_sim("hoper")
    with pytest.raises(ConfigError, match="no metaworld expert for 'hoper'"):
        expert("hoper")


@pytest.mark.parametrize(("action", "message"), [
    (np.zeros(3), "action: 3 values, the sim takes 4"),
    (np.zeros((2, 4)), "action: 8 values, the sim takes 4"),
    (np.array([0.0, np.nan, 0.0, 0.0]), r"action\[1\] is nan"),
])
def test_a_bad_action_is_refused_clearly(pick_place: Sim, action: np.ndarray,
                                         message: str) -> None:
    pick_place.reset(seed=0)
    with pytest.raises(InvalidInput, match=message):
        pick_place.step(action)
    assert not pick_place.step(np.zeros(4)).done  # the episode goes on


def test_a_step_before_reset_is_refused() -> None:
    sim = open_sim("inverted-double-pendulum")
    try:
        with pytest.raises(InvalidInput, match="inverted-double-pendulum: the episode is over"):
            sim.step(np.zeros(1))
    finally:
        sim.close()
