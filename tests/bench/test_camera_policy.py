"""A policy that sees: reacher-camera's target is only in its camera's image, so the policy
behaviour-cloned from image and state reaches it closed loop through the gateway's control
loop (the image going with each request), and with the image blanked it does not."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import onnxruntime
import pytest

from oricf.bench import camera_net, control
from oricf.bench.chunk_mlp import Fit
from oricf.bench.control_report import Row, goals
from oricf.bench.control_run import BLIND, MODES, run_episode, setting
from oricf.bench.sims import open_sim
from oricf.bench.sims.reacher_camera import ReacherCameraSim
from oricf.bench.train_camera_policy import Settings, cache_key, train_or_find
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.store import ModelStore
from tests.support.chunk_policy import session_root
from tests.support.reacher_policy import SETTINGS, reacher_policy

SEEDS = range(6)  # held out: the demonstrations start at 1,000,000


@pytest.fixture(scope="module")
def declaration() -> Path:
    return reacher_policy()


@pytest.fixture(scope="module")
def reacher_model(declaration: Path) -> Iterator[PolicyModel]:
    model = PolicyModel(load_declaration(declaration), ModelStore(session_root()))
    model.load()
    yield model
    model.close()


@pytest.fixture(scope="module")
def sim() -> Iterator[ReacherCameraSim]:
    reacher = ReacherCameraSim()
    yield reacher
    reacher.close()


def successes(sim: ReacherCameraSim, policy: PolicyModel, mode: str, delay: int = 0) -> int:
    chunk = policy.task.chunk
    return sum(run_episode(sim, policy, setting(mode, delay, chunk), seed,
                           sim.max_steps).success for seed in SEEDS)


def test_the_policy_reaches_the_target_it_sees_and_not_without_its_camera(
        sim: ReacherCameraSim, reacher_model: PolicyModel) -> None:
    assert reacher_model.cameras == ["top"] and reacher_model.task.state.size == sim.state_size == 6
    assert successes(sim, reacher_model, "onboard") >= 4
    assert successes(sim, reacher_model, BLIND) <= 2


def test_on_the_edge_the_image_goes_with_each_request(sim: ReacherCameraSim,
                                                      reacher_model: PolicyModel) -> None:
    """Behind a round trip of a step each request carries the image captured with its
    state, and the chunk that answers it still reaches the target."""
    assert successes(sim, reacher_model, "edge-sync", delay=1) >= 4


def test_the_same_settings_find_the_cache_and_train_nothing(declaration: Path) -> None:
    model = declaration.with_name("policy.onnx")
    written = model.stat().st_mtime_ns
    again = train_or_find(Settings(**SETTINGS), session_root())  # type: ignore[arg-type]
    assert (again.declaration, again.trained) == (declaration, False)
    assert model.stat().st_mtime_ns == written
    other = Settings(seed=1, **SETTINGS)  # type: ignore[arg-type]
    assert cache_key(other) != declaration.parent.name


def test_the_onnx_model_answers_what_the_numpy_net_answers() -> None:
    rng = np.random.default_rng(0)
    size, n = (8, 6), 32
    states, targets = rng.normal(size=(n, 3)), rng.normal(size=(n, 4))
    images = rng.uniform(size=(n, 3, size[0] * size[1]))
    net = camera_net.train(states, images, targets, [16], 2, Fit(2, 8), 0, size, 1)
    session = onnxruntime.InferenceSession(camera_net.to_onnx(net, 3, size, "net"),
                                           providers=["CPUExecutionProvider"])
    onnx_answer = session.run(None, {
        "state": states.astype(np.float32),
        "image": images.reshape(n, 3, size[1], size[0]).astype(np.float32)})[0]
    expected = camera_net.act(net, states, images, camera_net.grid(size[1], size[0]))
    np.testing.assert_allclose(onnx_answer, expected, rtol=1e-4, atol=1e-5)


def test_the_camera_shows_the_target_the_state_leaves_out(sim: ReacherCameraSim) -> None:
    state = sim.reset(seed=0)
    assert sim.cameras == ("top",) and state.shape == (6,)
    image = sim.images()["top"]
    assert image.shape == (32, 32, 3) and image.dtype == np.uint8
    blue, green, red = (image[:, :, i].astype(int) for i in range(3))
    red = (red > 100) & (red > 4 * green) & (red > 4 * blue)  # the target's disc, shaded
    rows, cols = np.nonzero(red)
    assert rows.size > 0
    x, y = sim.target()  # the red disc is where the target is: +x right, +y up
    half = 0.23
    assert abs((cols.mean() + 0.5) / 32 * 2 * half - half - x) < 0.03
    assert abs(half - (rows.mean() + 0.5) / 32 * 2 * half - y) < 0.03


def test_a_sim_without_cameras_reports_none() -> None:
    hopper = open_sim("hopper")
    try:
        hopper.reset(seed=0)
        assert hopper.cameras == () and hopper.images() == {}
    finally:
        hopper.close()


def test_the_bench_adds_the_blind_row_only_where_there_is_a_camera() -> None:
    assert control.task_modes("reacher-camera", list(MODES)) == \
        [m for m in MODES if m != "edge-ahead"] + [BLIND]
    assert BLIND not in control.task_modes("hopper", list(MODES))
    assert control.plan(["onboard", BLIND, "edge-latest"], {50.0: 4}, {}) == \
        [("onboard", 0), (BLIND, 0), ("edge-latest", 4)]


def test_in_real_time_the_loop_subscribes_to_the_simulated_robots_camera() -> None:
    from oricf.bench.control_realtime import control_input

    settings = control_input(60.6, 6, 2, 8, ("top",))
    assert settings["images"] == [{"name": "top", "topic": "/sim/top/image"}]
    assert control_input(60.6, 15, 3, 1)["images"] == []


@pytest.mark.bench
def test_realtime_rows_for_a_policy_that_sees(tmp_path: Path) -> None:
    """--realtime with reacher-camera: the simulated robot publishes its camera's view beside
    its state over ROS 2 and the gateway's loop sends both to the policy service; the arm
    reaches the target behind a one-step round trip."""
    out = tmp_path / "rows.json"
    assert control.main(["--task", "reacher-camera", "--delays-ms", "16.5", "--episodes", "2",
                         "--modes", "onboard", "--realtime", "--json", str(out)]) == 0
    rows = {row["mode"]: row for row in json.loads(out.read_text())}
    assert {"realtime-onboard", "realtime-edge"} <= set(rows)
    assert float(rows["realtime-edge"]["success_rate"]) > 0


def test_the_metaworld_goals_leave_reacher_camera_out() -> None:
    def row(mode: str, delay_ms: float, success: float) -> Row:
        return Row("reacher-camera", mode, delay_ms, 4 if delay_ms else 0, 10, success, 20.0,
                   30.0, 5.0, 7.0, 4.0, 100.0, 30.0, 0.4, 30.0)
    rows = [row("onboard", 0.0, 0.9), row("edge-latest", 50.0, 0.2)]
    behind_50 = goals(rows)[1]
    assert behind_50.status == "not measured" and "reacher-camera" not in behind_50.name
