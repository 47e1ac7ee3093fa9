"""The behaviour-cloned chunk policy: trained from a metaworld expert's demonstrations into
a model root, served by the real policy model class, solving its task closed loop, and
found in the cache the second time instead of trained again."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from oricf.bench.chunk_demos import chunks
from oricf.bench.sims import open_sim
from oricf.bench.train_chunk_policy import (
    Settings,
    cache_key,
    declaration_text,
    train_or_find,
    trained_policy,
)
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.store import ModelStore
from tests.support.chunk_policy import SMALL, TASK, session_root


@pytest.fixture(scope="module")
def root() -> Path:
    """The session's model root: the policy is trained once for every test that asks."""
    return session_root()


@pytest.fixture(scope="module")
def declaration(root: Path) -> Path:
    return trained_policy(TASK, root=root, **SMALL)


def test_the_trained_policy_solves_its_task_closed_loop(root: Path, declaration: Path) -> None:
    assert declaration.parent.parent == root / "trained"
    policy = PolicyModel(load_declaration(declaration), ModelStore(root))
    policy.load()
    sim = open_sim(TASK)
    try:
        assert policy.info().parameters["chunk"] == "16"
        assert policy.task.state.size == sim.state_size and policy.task.rate_hz == sim.rate_hz
        observation = sim.reset(seed=0)
        done = False
        while not done:  # every action of a chunk, then a new chunk
            chunk = policy.act(observation)
            assert chunk.shape == (16, 4)
            for action in chunk:
                step = sim.step(action)
                observation, done = step.observation, step.done
                if done:
                    break
        assert step.success
    finally:
        sim.close()
        policy.close()


def test_the_same_settings_find_the_cache_and_train_nothing(root: Path,
                                                            declaration: Path) -> None:
    model = declaration.with_name("policy.onnx")
    written = model.stat().st_mtime_ns
    again = train_or_find(Settings(task=TASK, **SMALL), root)
    assert (again.declaration, again.trained) == (declaration, False)
    assert model.stat().st_mtime_ns == written
    assert cache_key(Settings(task=TASK, seed=1, **SMALL)) != declaration.parent.name


def test_a_chunk_past_the_episodes_end_repeats_its_last_action() -> None:
    actions = np.arange(6, dtype=float).reshape(3, 2)  # three steps of two values
    np.testing.assert_array_equal(chunks(actions, 2), [[0, 1, 2, 3], [2, 3, 4, 5],
                                                       [4, 5, 4, 5]])


def test_a_lead_shifts_the_targets_to_the_actions_that_many_steps_later() -> None:
    actions = np.arange(10, dtype=float).reshape(5, 2)  # five steps of two values
    np.testing.assert_array_equal(chunks(actions, 2, lead=2), [[4, 5, 6, 7], [6, 7, 8, 9],
                                                               [8, 9, 8, 9], [8, 9, 8, 9],
                                                               [8, 9, 8, 9]])
    np.testing.assert_array_equal(chunks(actions, 3, lead=0), chunks(actions, 3))


def test_the_lead_is_in_the_cache_key_and_the_declaration(tmp_path: Path) -> None:
    assert cache_key(Settings(task=TASK, lead=8, **SMALL)) != \
        cache_key(Settings(task=TASK, **SMALL))
    model = tmp_path / "policy.onnx"
    model.write_bytes(b"weights")  # only named by the declaration: never loaded here
    text = declaration_text(Settings(task=TASK, lead=8), "k" * 20, model, np.zeros(39),
                            np.ones(39))
    declaration = tmp_path / "policy.yaml"
    declaration.write_text(text)
    assert load_declaration(declaration).task.lead_steps == 8  # type: ignore[union-attr]
