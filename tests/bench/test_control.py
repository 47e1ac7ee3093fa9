"""`oricf bench control` on pybullet's real Hopper policy in the real simulator, through
the gateway's control loop in simulated time: short episodes, a fixed seed, so the figures
do not depend on the machine's speed (only the CPU does, and nothing asserts on it)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from oricf.bench import control, control_realtime
from oricf.bench.control_report import Row, summarise
from oricf.bench.control_run import MODES, delay_steps, placement, run_episode, setting
from oricf.bench.sims import Sim, open_sim
from oricf.bench.train_chunk_policy import trained_policy
from oricf.bench.train_committed_policy import committed_policy
from oricf.errors import ConfigError
from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.store import ModelStore
from tests.support.chunk_policy import SMALL, TASK, session_root

STEPS = 300  # Hopper hops forward well within this
EDGE_MODES = ["edge-sync", "edge-latest", "edge-weighted", "edge-ensemble", "placed"]


def bench(tmp_path: Path, *args: str) -> list[dict[str, object]]:
    out = tmp_path / "rows.json"
    assert control.main(["--task", "hopper", "--episodes", "1", "--max-steps", str(STEPS),
                         "--json", str(out), *args]) == 0
    rows: list[dict[str, object]] = json.loads(out.read_text())
    return rows


@pytest.fixture(scope="module")
def rows(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, object]]:
    # 0 and 1 step at 60.6 Hz
    return bench(tmp_path_factory.mktemp("control"), "--delays-ms", "0,16.5")


def row(rows: list[dict[str, object]], mode: str, steps: int) -> dict[str, object]:
    [found] = [r for r in rows if r["mode"] == mode and r["delay_steps"] == steps]
    return found


def test_a_row_per_mode_and_delay_with_every_field(rows: list[dict[str, object]]) -> None:
    fields = set(Row.__dataclass_fields__)
    assert all(set(r) == fields for r in rows)
    expected = [("onboard", 0)] + [(m, d) for d in (0, 1) for m in EDGE_MODES]
    assert [(r["mode"], r["delay_steps"]) for r in rows] == expected
    assert all(r["task"] == "hopper" and r["episodes"] == 1 for r in rows)
    assert all(r["success_rate"] is None for r in rows)  # a return, no success


def test_onboard_the_policy_hops_the_whole_episode(rows: list[dict[str, object]]) -> None:
    onboard = row(rows, "onboard", 0)
    assert onboard["mean_steps"] == STEPS and onboard["mean_return"] > 500  # type: ignore[operator]
    assert onboard["action_age_p99"] == 0 and onboard["empty_ticks"] == 0


def test_a_client_unaware_of_one_step_of_delay_makes_hopper_fall(
        rows: list[dict[str, object]]) -> None:
    onboard, sync = row(rows, "onboard", 0), row(rows, "edge-sync", 1)
    assert sync["mean_return"] < 0.5 * onboard["mean_return"]  # type: ignore[operator]
    assert sync["mean_steps"] < STEPS  # type: ignore[operator]
    assert sync["action_age_p50"] == 1


def test_skipping_late_actions_leaves_a_one_action_policy_nothing_to_play(
        rows: list[dict[str, object]]) -> None:
    latest = row(rows, "edge-latest", 1)
    # every answer's one action is for a step already played; the first tick waits too
    assert latest["late_actions"] == latest["empty_ticks"] - 1  # type: ignore[operator]
    assert latest["action_age_p50"] is None


def test_an_edge_over_a_one_step_budget_leaves_hopper_onboard_and_says_why(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = bench(tmp_path, "--delays-ms", "30", "--budget-steps", "1", "--modes", "placed")
    onboard, placed = row(rows, "onboard", 0), row(rows, "placed", 2)
    assert placed["placed_onboard"] is True and placed["budget_steps"] == 1
    assert placed["mean_return"] == pytest.approx(onboard["mean_return"], rel=1e-3)
    reason = ("onboard: the edge's round trip of 30 ms (2 steps) is over the budget of "
              "16.5 ms (1 steps at 60.6061 Hz)")
    assert placed["reason"] == reason and reason in capsys.readouterr().out


def test_within_its_budget_the_policy_is_placed_on_the_edge(
        rows: list[dict[str, object]]) -> None:
    placed, sync = row(rows, "placed", 1), row(rows, "edge-sync", 1)
    assert placed["placed_onboard"] is False
    assert str(placed["reason"]).startswith("edge (edge-sync): the edge's round trip of "
                                            "16.5 ms (1 step) is within the budget")
    assert placed["mean_return"] == sync["mean_return"]


def test_a_round_trip_is_whole_steps() -> None:
    pybullet = 1 / 0.0165
    assert [delay_steps(ms, pybullet) for ms in (0, 16.5, 17, 30, 33, 66, 132)] == \
        [0, 1, 2, 2, 2, 4, 8]
    assert [delay_steps(ms, 80.0) for ms in (50, 100, 200)] == [4, 8, 16]
    assert placement(16.5, pybullet, 1, chunk=1).mode == "edge-sync"
    assert placement(100, 80.0, 8, chunk=16).mode == "edge-latest"
    assert placement(101, 80.0, 8, chunk=16).mode == "onboard"


@pytest.mark.parametrize(("args", "message"), [
    (["--task", "walker"], "--task walker: no such simulator"),
    (["--delays-ms", "0,fast"], "--delays-ms: 'fast' is not a number of milliseconds"),
    (["--delays-ms", "-5"], "--delays-ms: -5: must be 0 or more milliseconds"),
    (["--modes", "edge-lazy"], "--modes: edge-lazy: the modes are onboard"),
])
def test_bad_input_is_one_line(args: list[str], message: str) -> None:
    with pytest.raises(ConfigError, match="^" + re.escape(message)):
        control.options(args)


def test_the_command_says_it_in_one_line_and_exits_2() -> None:
    done = subprocess.run([sys.executable, "-m", "oricf", "bench", "control", "--task",
                           "walker"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--task walker: no such simulator" in lines[0], done.stderr


@pytest.fixture(scope="module")
def drawer_root() -> Path:
    return session_root()


def drawer_policy(root: Path, lead: int) -> PolicyModel:
    """A small chunk policy for metaworld's drawer-close-v3 (the settings
    tests/bench/test_chunk_policy.py trains: quick, and far from the edge), acting `lead`
    steps ahead."""
    declaration = trained_policy(TASK, root=root, lead=lead, **SMALL)
    policy = PolicyModel(load_declaration(declaration), ModelStore(root))
    policy.load()
    return policy


@pytest.fixture(scope="module")
def drawer(drawer_root: Path) -> Iterator[tuple[Sim, dict[str, PolicyModel]]]:
    """The simulator, and the policy of each mode: edge-ahead's trained to act the round
    trip of 50 ms (4 steps) ahead."""
    committed = committed_policy(TASK, root=drawer_root, lead=4, rounds=1, rollouts=3,
                                 rollout_steps=120, **SMALL)
    policies = {"plain": drawer_policy(drawer_root, 0), "edge-ahead": drawer_policy(drawer_root, 4),
                "edge-committed": PolicyModel(load_declaration(committed), ModelStore(drawer_root))}
    policies["edge-committed"].load()
    sim = open_sim("drawer-close-v3")
    yield sim, policies
    sim.close()
    for policy in policies.values():
        policy.close()


@pytest.mark.parametrize(("mode", "steps"), [("onboard", 0), ("edge-latest", 4),
                                             ("edge-ensemble", 4), ("edge-sync", 4),
                                             ("edge-ahead", 4), ("edge-committed", 4)])
def test_a_chunk_policy_closes_the_drawer_through_the_loop_behind_50_ms(
        drawer: tuple[Sim, dict[str, PolicyModel]], mode: str, steps: int) -> None:
    sim, policies = drawer
    policy = policies.get(mode, policies["plain"])
    assert delay_steps(50, sim.rate_hz) == steps or mode == "onboard"
    episodes = [run_episode(sim, policy, setting(mode, steps, policy.task.chunk), seed, 500)
                for seed in (0, 1)]
    result = summarise("drawer-close-v3", mode, 50, steps, episodes, metaworld=True)
    assert result.success_rate == 1.0
    assert all(e.steps == e.ticks < 500 for e in episodes)  # it ended at its success
    if mode == "edge-sync":  # unaware: the last action held while each chunk is on its way
        assert result.empty_ticks > steps and result.late_actions == 0
    else:  # asked ahead: dry only while the first answer was on its way
        assert result.empty_ticks == steps
    if mode in ("edge-latest", "edge-ensemble"):  # delay-aware: the late actions dropped
        assert result.late_actions > 0
        assert result.action_age_p50 is not None and steps <= result.action_age_p50 < 2 * steps
    if mode in ("edge-ahead", "edge-committed"):  # each chunk starts as it arrives
        assert result.late_actions == 0
        assert result.action_age_p50 is not None and steps <= result.action_age_p50 < 2 * steps


def test_the_mode_acting_ahead_runs_where_a_policy_can_be_trained_for_it() -> None:
    assert "edge-ahead" in control.task_modes("pick-place-v3", list(MODES))
    assert control.task_modes("hopper", list(MODES)) == [m for m in MODES if m != "edge-ahead"]
    runs = control.plan(["onboard", "edge-ahead"], {0.0: 0, 100.0: 8}, {})
    assert runs == [("onboard", 0), ("edge-ahead", 0), ("edge-ahead", 8)]


@pytest.mark.bench
def test_realtime_rows_come_from_the_gateway_and_the_robot_over_ros(tmp_path: Path) -> None:
    """--realtime: the policy service behind the relay, the gateway's loop in its process, the
    simulator as a ROS 2 robot; its rows beside the simulated ones, the gateway on each of
    rclpy's executors in turn."""
    rows = bench(tmp_path, "--delays-ms", "33", "--modes", "onboard", "--realtime",
                 "--executor", "both")
    realtime = {(row["mode"], row["executor"]): row for row in rows
                if str(row["mode"]).startswith("realtime")}
    assert set(realtime) == {(mode, executor) for mode in ("realtime-onboard", "realtime-edge")
                             for executor in ("python", "events")}
    for executor in ("python", "events"):
        onboard = realtime["realtime-onboard", executor]
        edge = realtime["realtime-edge", executor]
        assert (onboard["delay_ms"], edge["delay_ms"], edge["delay_steps"]) == (0.0, 33.0, 2)
        for row in (onboard, edge):
            assert row["episodes"] == 1 and float(row["mean_steps"]) > 0  # type: ignore[arg-type]
            assert float(row["cpu_us_per_tick"]) > 0  # type: ignore[arg-type]
        # The loop's own work, measured on its threads, is part of the gateway's CPU: the
        # ticks' and the requests' each.
        assert 0 < float(edge["loop_cpu_us_per_tick"]) < float(edge["cpu_us_per_tick"])  # type: ignore[arg-type]
        assert float(edge["loop_tick_cpu_us"]) > 0 and float(edge["request_cpu_us"]) > 0  # type: ignore[arg-type]


def test_the_policy_taking_the_committed_actions_is_cached_and_declares_them(
        drawer: tuple[Sim, dict[str, PolicyModel]], drawer_root: Path) -> None:
    settings = {"lead": 4, "rounds": 1, "rollouts": 3, "rollout_steps": 120, **SMALL}
    declaration = committed_policy(TASK, root=drawer_root, **settings)  # the fixture's
    written = declaration.stat().st_mtime_ns
    assert committed_policy(TASK, root=drawer_root, **settings) == declaration
    assert declaration.stat().st_mtime_ns == written  # found, not trained again
    task = load_declaration(declaration).task
    assert task.committed is not None and task.committed.steps == 4  # type: ignore[union-attr]
    assert task.lead_steps == 4  # type: ignore[union-attr]
    training = json.loads((declaration.parent / "training.json").read_text())
    assert training["rounds"] == 1 and training["dagger_pairs"] > 0  # the rollouts' joined


def test_in_real_time_the_trained_modes_ask_as_their_chunk_arrives_and_committed_sends_them(
        ) -> None:
    """The loop's settings in real time are the simulated loop's (control_run.setting): a
    policy trained to act ahead is asked again as soon as its chunk is in; edge-committed
    sends the actions committed with each request, the others do not."""
    chunk = 16
    for mode in ("onboard", "edge-latest", "edge-ahead", "edge-committed"):
        simulated = setting(mode, 4, chunk)
        loop = control_realtime.control_input(80.0, 39, 4, chunk, (), mode)
        assert loop["request_at"] == simulated.request_at
        assert loop["send_committed"] is simulated.send_committed is (mode == "edge-committed")
    assert [control_realtime.realtime_mode(m, ms) for m, ms in [
        ("edge-latest", 0.0), ("edge-latest", 50.0), ("edge-committed", 50.0)]] == [
        "realtime-onboard", "realtime-edge", "realtime-edge-committed"]


@pytest.mark.bench
def test_realtime_edge_committed_runs_its_trained_policy_over_ros(drawer_root: Path) -> None:
    """--realtime --modes edge-committed: the policy trained for the round trip (the
    drawer fixture's, behind 4 steps) served behind the relay, the gateway sending the
    actions committed with each request, the simulator as a ROS 2 robot."""
    declaration = committed_policy(TASK, root=drawer_root, lead=4, rounds=1, rollouts=3,
                                   rollout_steps=120, **SMALL)  # the drawer fixture's
    rows = control_realtime.realtime_rows(
        TASK, [control_realtime.Plan("edge-committed", declaration, (50.0,))], episodes=1,
        seed=0, metaworld=True, max_steps=120)
    assert [(r.mode, r.delay_ms, r.delay_steps, r.executor) for r in rows] == [
        ("realtime-edge-committed", 50.0, 4, "events")]
    assert rows[0].mean_steps is not None and rows[0].switches > 0  # chunks came and played
