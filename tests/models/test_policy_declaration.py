"""A declared policy (`task: {kind: policy}`): the shipped ones load and agree with their
model files; a declaration that disagrees with its file, or with itself, is refused naming
the file and the key."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from oricf.config import REPO_ROOT
from oricf.errors import ConfigError, InvalidInput
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel, committed_window
from oricf.store import ModelStore
from tests.support.camera_policy import CAMERA, committed_declaration
from tests.support.camera_policy import declaration as camera_policy

POLICIES = REPO_ROOT / "configs" / "models" / "policies"
HOPPER = POLICIES / "hopper.yaml"


@pytest.mark.parametrize(("file", "state", "action"), [
    ("hopper.yaml", 15, 3), ("ant.yaml", 28, 8), ("inverted-double-pendulum.yaml", 9, 1)])
def test_the_shipped_policies_load_and_act_within_their_bounds(file: str, state: int,
                                                               action: int) -> None:
    policy = PolicyModel(load_declaration(POLICIES / file), ModelStore())
    policy.load()
    assert (policy.task.state.size, policy.task.action.dim, policy.task.chunk) == (
        state, action, 1)
    assert policy.task.rate_hz == pytest.approx(1 / 0.0165, abs=1e-3)  # pybullet_envs' step
    actions = policy.act(np.full(state, 10.0, np.float32))  # far outside what it was trained on
    assert actions.shape == (1, action) and abs(actions).max() <= 1.0


def changed(tmp_path: Path, **task: Any) -> Path:
    data = yaml.safe_load(HOPPER.read_text())
    for key, value in task.items():
        if isinstance(value, dict):
            data["task"][key] = {**data["task"][key], **value}
        else:
            data["task"][key] = value
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(("task", "message"), [
    ({"state": {"size": 14}}, "mine.yaml: task.state.size: 14, the model input 'observation' "
                              "takes 15 values"),
    ({"action": {"dim": 4}}, "mine.yaml: task.action.dim: 1 x 4 actions, the model output "
                             "'action' gives 3 values"),
    ({"chunk": 4}, "mine.yaml: task.chunk: 4 x 3 actions, the model output 'action' gives 3"),
    ({"state": {"input": "obs"}}, "mine.yaml: task.state.input: the model has no input 'obs' "
                                  "(inputs: observation)"),
    ({"action": {"output": "act"}}, "mine.yaml: task.action.output: the model has no output "
                                    "'act' (outputs: action)"),
], ids=["state size", "action dim", "chunk", "state input", "action output"])
def test_a_declaration_that_disagrees_with_its_model_file_is_refused_at_load(
        tmp_path: Path, task: dict[str, Any], message: str) -> None:
    policy = PolicyModel(load_declaration(changed(tmp_path, **task)), ModelStore())
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        policy.load()


@pytest.mark.parametrize(("task", "message"), [
    ({"state": {"mean": [0.0] * 3}}, r"task\.policy\.state: mean: 3 values, size is 15"),
    ({"state": {"std": [0.0] * 15}}, r"task\.policy\.state: std: every value must be > 0"),
    ({"action": {"low": [0.0, 0.0]}}, r"task\.policy\.action: low: 2 values, dim is 3"),
    ({"action": {"low": 2.0}}, r"task\.policy\.action: low: above high"),
    ({"images": [{"name": "top"}, {"name": "top"}]},
     r"task\.policy\.images: the name top is given twice"),
    ({"images": [{"name": "top"}, {"name": "wrist"}]},
     r"task\.policy\.images: with more than one camera, each names its input"),
    ({"images": [{"name": "top camera"}]}, r"task\.policy\.images\[0\]\.name: String should "
                                          r"match pattern"),
    ({"rate_hz": 0}, r"task\.policy\.rate_hz: Input should be greater than 0"),
    ({"lead_steps": -1}, r"task\.policy\.lead_steps: Input should be greater than or equal "
                         r"to 0"),
    ({"lead_steps": 1025}, r"task\.policy\.lead_steps: Input should be less than or equal "
                           r"to 1024"),
], ids=["mean", "std", "bounds", "low above high", "camera twice", "inputs unnamed",
        "camera name", "rate", "lead below 0",
        "lead too far"])
def test_a_declaration_at_odds_with_itself_is_refused_naming_file_and_key(
        tmp_path: Path, task: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError, match=f"mine.yaml: {message}"):
        load_declaration(changed(tmp_path, **task))


def test_a_policy_acts_on_what_it_sees_unless_declared_to_act_ahead(tmp_path: Path) -> None:
    assert load_declaration(HOPPER).task.lead_steps == 0  # type: ignore[union-attr]
    ahead = PolicyModel(load_declaration(changed(tmp_path, lead_steps=8)), ModelStore())
    assert ahead.task.lead_steps == 8 and ahead.info().parameters["lead_steps"] == "8"


def test_the_policy_service_refuses_a_model_that_is_no_policy() -> None:
    yolox = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"
    with pytest.raises(ConfigError, match=r"yolox-nano.yaml: task.kind: the policy service "
                                          r"serves policies"):
        PolicyModel(load_declaration(yolox), ModelStore())


def test_normalisation_is_applied_before_the_model(tmp_path: Path) -> None:
    plain = PolicyModel(load_declaration(HOPPER), ModelStore())
    shifted = PolicyModel(load_declaration(changed(
        tmp_path, state={"mean": [1.0] * 15, "std": [2.0] * 15})), ModelStore())
    plain.load()
    shifted.load()
    state = np.linspace(-1.0, 2.0, 15, dtype=np.float32)
    assert abs(plain.act(state) - plain.act((state - 1.0) / 2.0)).max() > 0.01
    np.testing.assert_allclose(shifted.act(state), plain.act((state - 1.0) / 2.0), atol=1e-6)


@pytest.mark.parametrize(("task", "message"), [
    ({"images": []}, "task.images: the model input image is neither the state nor a camera's"),
    ({"images": [{"name": "top", "input": "picture"}]},
     r"task.images\[0\].input: the model has no image input 'picture' \(image inputs: image\)"),
    ({"images": [{"name": "top", "size": [16, 16]}]},
     r"task.images\[0\].size: \[16, 16\], the model input 'image' takes 8x8"),
    ({"images": [{"name": "top", "datatype": "UINT8"}]},
     "task.images\\[0\\].datatype: UINT8, the model input 'image' is FP32"),
    ({"images": [{"name": "top", "size": [8, 8], "layout": "nhwc"}]},
     r"task.images\[0\].layout: nhwc, the model input 'image' is shaped \[-1, 3, 8, 8\]"),
    ({"images": [{"name": "top", "size": [8, 8]}, {"name": "wrist", "input": "wrist"}]},
     r"task\.policy\.images: with more than one camera, each names its input"),
], ids=["no camera", "no such input", "size", "datatype", "layout", "unnamed inputs"])
def test_a_camera_that_disagrees_with_its_model_input_is_refused_at_load(
        tmp_path: Path, task: dict[str, Any], message: str) -> None:
    try:
        policy = PolicyModel(load_declaration(camera_policy(tmp_path, **task)), ModelStore())
    except ConfigError as exc:  # caught by the schema already
        assert re.search(message, str(exc)), exc
        return
    with pytest.raises(ConfigError, match=f"policy.yaml: {message}"):
        policy.load()


def test_a_policy_with_a_camera_is_fed_its_image_as_declared(tmp_path: Path) -> None:
    policy = PolicyModel(load_declaration(camera_policy(tmp_path)), ModelStore())
    policy.load()
    assert policy.cameras == [CAMERA]
    blue_left = np.zeros((40, 60, 3), np.uint8)
    blue_left[:, :30, 0] = 255  # BGR: the left half blue
    actions = policy.act(np.array([0.5, -2.0], np.float32), {CAMERA: blue_left})
    np.testing.assert_allclose(actions, [[0.0, 0.0, 0.5, 0.5, -2.0]], atol=1e-6)
    with pytest.raises(InvalidInput, match=f"images: no image from camera {CAMERA}"):
        policy.act(np.zeros(2, np.float32))


def test_committed_actions_that_disagree_with_their_model_input_are_refused_at_load(
        tmp_path: Path) -> None:
    declaration = committed_declaration(tmp_path, steps=3)
    data = yaml.safe_load(declaration.read_text())
    data["task"]["committed"]["steps"] = 4
    declaration.write_text(yaml.safe_dump(data))
    policy = PolicyModel(load_declaration(declaration), ModelStore())
    with pytest.raises(ConfigError, match=r"committed.yaml: task.committed.steps: 4 x 2 "
                                          r"actions, the model input 'committed' takes 6"):
        policy.load()


def test_the_committed_window_holds_each_action_at_its_step_and_zeros_elsewhere() -> None:
    actions = np.array([[1.0, 1.0], [2.0, 2.0]])
    assert committed_window((1, actions), 4, 2).tolist() == [[0, 0], [1, 1], [2, 2], [0, 0]]
    assert committed_window((-1, actions), 2, 2).tolist() == [[2, 2], [0, 0]]  # one played
    assert committed_window(None, 2, 2).tolist() == [[0, 0], [0, 0]]
