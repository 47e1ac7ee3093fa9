"""MLP weights as numpy literals in a Python file (pybullet's trained policies) made into
ONNX: the real wheel members against pybullet's own arrays, made once, never executed, and
every broken file refused naming the file and the array."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest

from oricf.errors import ConfigError
from oricf.models.mlp_source import check_chain, converted, read_arrays
from oricf.store import ModelStore, sha256_of
from tests.support.pybullet_sim import forward, hopper, reference_arrays
from tests.support.waiting import wait_for

POLICIES = [("pybullet-hopper", "HopperBulletEnv_v0", 15, 3),
            ("pybullet-ant", "AntBulletEnv_v0", 28, 8),
            ("pybullet-inverted-double-pendulum", "InvertedDoublePendulumBulletEnv_v0", 9, 1)]


def run_onnx(path: Path, observation: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    result = session.run(["action"], {"observation": observation.reshape(1, -1)})[0]
    return np.asarray(result)[0]


@pytest.mark.parametrize(("catalog", "env", "obs", "act"), POLICIES,
                         ids=[p[0] for p in POLICIES])
def test_the_wheels_policy_becomes_onnx_that_acts_as_its_arrays_do(
        catalog: str, env: str, obs: int, act: int) -> None:
    store = ModelStore()
    source = store.path(catalog)
    arrays, module_file = reference_arrays(env)
    # The installed module is the very member the catalog names.
    assert sha256_of(module_file) == sha256_of(source)
    onnx_file = converted(source, sha256_of(source), catalog)
    observation = np.random.default_rng(1).normal(size=obs).astype(np.float32)
    action = run_onnx(onnx_file, observation)
    assert action.shape == (act,)
    np.testing.assert_allclose(action, forward(arrays, observation), rtol=1e-5, atol=1e-5)


def test_on_a_real_hopper_observation() -> None:
    source = ModelStore().path("pybullet-hopper")
    arrays, _ = reference_arrays("HopperBulletEnv_v0")
    env = hopper(seed=3)
    env.reset()
    observation, *_ = env.step(np.zeros(3))  # a moving hopper, not the rest pose
    observation = np.asarray(observation, np.float32)
    action = run_onnx(converted(source, sha256_of(source), "pybullet-hopper"), observation)
    np.testing.assert_allclose(action, forward(arrays, observation), rtol=1e-5, atol=1e-5)


def test_it_is_made_once_keyed_by_the_sources_sha256(tmp_path: Path) -> None:
    source = tmp_path / "weights.py"
    source.write_bytes(ModelStore().path("pybullet-inverted-double-pendulum").read_bytes())
    digest = sha256_of(source)
    first = converted(source, digest, "pendulum")
    assert first.name == f"{digest}.onnx"
    made = first.stat().st_mtime_ns
    source.write_text("not even Python (")  # the cached model is used, the source not read
    assert converted(source, digest, "pendulum").stat().st_mtime_ns == made


# One converting process; with a folder as its third argument, it is held between writing
# the model and renaming it into place (`held` there says it is waiting, `go` lets it on).
CONVERT = """
import os, sys, time
from pathlib import Path
from oricf.models.mlp_source import converted
source, digest, hold = Path(sys.argv[1]), sys.argv[2], sys.argv[3:]
if hold:
    rename = os.replace
    def held(src, dst):
        Path(hold[0], "held").touch()
        while not Path(hold[0], "go").exists():
            time.sleep(0.01)
        rename(src, dst)
    os.replace = held
print(converted(source, digest, "pendulum"))
"""


def test_two_processes_converting_one_file_at_once_both_succeed(tmp_path: Path) -> None:
    source = tmp_path / "weights.py"
    source.write_bytes(ModelStore().path("pybullet-inverted-double-pendulum").read_bytes())
    digest, hold = sha256_of(source), tmp_path / "hold"
    hold.mkdir()
    command = [sys.executable, "-c", CONVERT, str(source), digest]
    first = subprocess.Popen([*command, str(hold)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: (hold / "held").exists() or first.poll() is not None, 120,
                 "the first converter written and held")
        # The second writes and renames its own while the first still holds its copy.
        second = subprocess.run(command, capture_output=True, text=True, timeout=120)
        (hold / "go").touch()
        out, err = first.communicate(timeout=120)
    finally:
        first.kill()
    target = tmp_path / f"{digest}.onnx"
    assert second.returncode == 0, second.stderr
    assert first.returncode == 0, err
    assert out.strip() == second.stdout.strip() == str(target)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    observation = np.zeros(9, np.float32)
    arrays = read_arrays(source)
    np.testing.assert_allclose(run_onnx(target, observation), forward(arrays, observation),
                               rtol=1e-5, atol=1e-5)


LAYER = "weights_dense1_w = np.array([[1.0, 2.0], [3.0, 4.0]])\n"
VALID = (LAYER + "weights_dense1_b = np.array([0.0, 0.0])\n"
         "weights_dense2_w = np.array([[1.0], [1.0]])\nweights_dense2_b = np.array([0.5])\n"
         "weights_final_w = np.array([[2.0, -2.0]])\nweights_final_b = np.array([0.0, 1.0])\n")


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "policy.py"
    path.write_text(text)
    return path


def test_a_small_valid_file_gives_its_sizes_and_actions(tmp_path: Path) -> None:
    path = write(tmp_path, VALID)
    arrays = read_arrays(path)
    assert check_chain(path, arrays) == (2, 2)
    observation = np.array([1.0, -1.0], np.float32)
    action = run_onnx(converted(path, sha256_of(path), "small"), observation)
    np.testing.assert_allclose(action, forward(arrays, observation))


def test_the_file_is_never_executed(tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    code = (f"open({str(marker)!r}, 'w').write('ran')\n" + VALID +
            f"weights_final_b = np.array(open({str(marker)!r}).read())\n")
    path = write(tmp_path, code)
    with pytest.raises(ConfigError, match=r"policy\.py: weights_final_b: not a numeric "
                                          r"array literal"):
        read_arrays(path)
    assert not marker.exists()


@pytest.mark.parametrize(("text", "message"), [
    (VALID.replace("weights_dense2_b = np.array([0.5])\n", ""),
     r"policy\.py: no array weights_dense2_b"),
    (VALID.replace("[[1.0], [1.0]]", "[[1.0], [1.0], [1.0]]"),
     r"policy\.py: weights_dense2_w: takes 3 values, the layer before gives 2"),
    (VALID.replace("np.array([0.5])", "np.array([0.5, 1.0])"),
     r"policy\.py: weights_dense2_b: shape \[2\], weights_dense2_w needs \[1\]"),
    (VALID.replace("[0.0, 1.0]", "[0.0, float('nan')]"),
     r"policy\.py: weights_final_b: not a numeric array literal"),
    (VALID.replace("[0.0, 1.0]", "[0.0, 1e999]"),
     r"policy\.py: weights_final_b: holds NaN or infinity"),
    (VALID.replace("[[2.0, -2.0]]", "[[2.0, 'x']]"),
     r"policy\.py: weights_final_w: not a numeric array literal"),
    ("def broken(:\n", r"policy\.py: cannot be parsed as Python"),
], ids=["missing", "chain", "bias", "call", "infinite", "text", "syntax"])
def test_a_broken_file_is_refused_naming_it_and_the_array(tmp_path: Path, text: str,
                                                          message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=message):
        converted(path, sha256_of(path), "mine")
    assert not list(tmp_path.glob("*.onnx"))
