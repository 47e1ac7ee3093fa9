"""The control input over real DDS: a Hopper observation of the real simulator published at
the policy's rate, the gateway's loop asking pybullet's trained policy (`oricf serve policy`)
and publishing its action on time; the safe action when the observation stops, turns bad or
the policy goes away, and last when the gateway stops; an edge that lies about the
observation it answers, or plants actions far ahead, steers nothing."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, closing, contextmanager
from typing import Any

import numpy as np
import pytest
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from oricf.bench.relay import DelayRelay
from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, parse_pipeline
from oricf.gateway.control.source import ControlSource
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.ros.executor import make_executor, spin_until_shutdown
from oricf.gateway.shells.ros_node import GatewayNode
from tests.gateway.ros.gateway_node import spinning, wait_for
from tests.support.chunk_policy import chunk_policy
from tests.support.hostile_edge import chunk, hostile_edge
from tests.support.metrics import scrape
from tests.support.pybullet_sim import forward, hopper, reference_arrays
from tests.support.services import RunningService, running_service

RATE_HZ = 60.606


def control_config(address: str, target: dict[str, Any] | None = None,
                   **settings: Any) -> PipelineConfig:
    control = {"rate_hz": RATE_HZ, "action_dim": 3, "max_age_ms": 200,
               "state": [{"topic": "/hopper/state", "type": "std_msgs/Float64MultiArray",
                          "size": 15}],
               "target": target or {"topic": "/hopper/action",
                                    "bounds": [[-1, 1]] * 3, "deadman_ms": 300}} | settings
    return parse_pipeline({
        "metrics": {"listen": "127.0.0.1:0"},
        "endpoints": {"hopper": {"address": address, "deadline_ms": 2000}},
        "routes": {"hopper": {"input": {"control": control},
                              "call": {"method": "Act", "service": "hopper"}}}},
        "test control pipeline")


class Robot:
    """The robot's side: its state published, every action it is sent collected."""

    def __init__(self, context: Context, action_type: Any = Float64MultiArray,
                 action_topic: str = "/hopper/action") -> None:
        self.node = Node("control_test_robot", context=context)
        self.actions: queue.Queue[Any] = queue.Queue()
        self.state = self.node.create_publisher(Float64MultiArray, "/hopper/state",
                                                QoSProfile(depth=1))
        self.node.create_subscription(action_type, action_topic, self.actions.put, 50)
        self.publishing: list[float] | None = None
        self.node.create_timer(1 / RATE_HZ, self._publish)

    def _publish(self) -> None:
        if self.publishing is not None:
            self.state.publish(Float64MultiArray(data=self.publishing))

    def drain(self) -> list[Any]:
        got = []
        while not self.actions.empty():
            got.append(self.actions.get())
        return got

    def next_actions(self, count: int, timeout: float = 10.0) -> list[Any]:
        return [self.actions.get(timeout=timeout) for _ in range(count)]

    def wait_steady(self, data: list[float], count: int = 5, timeout: float = 10.0) -> None:
        """Until `count` actions in a row are `data` (what was on its way before is let
        through: the loop's earlier ticks may still be in transit)."""
        deadline = time.monotonic() + timeout
        run = 0
        while run < count:
            assert time.monotonic() < deadline, f"no {count} actions {data} in a row"
            msg = self.actions.get(timeout=timeout)
            run = run + 1 if list(msg.data) == pytest.approx(data) else 0


def source_of(gateway: GatewayNode) -> ControlSource:
    source = gateway.gateway.inputs[0]
    assert isinstance(source, ControlSource)
    return source


class Running:
    """A gateway with a control input and the robot's node, spun on real DDS."""

    def __init__(self, gateway: GatewayNode) -> None:
        self.gateway = gateway
        self.source = source_of(gateway)
        self._stopped = False

    def stop(self) -> None:
        if not self._stopped:
            self._stopped = True
            self.gateway.shutdown()


@contextmanager
def running(config: PipelineConfig, context: Context, robot: Robot) -> Iterator[Running]:
    """The gateway node on the executor its config names, spun as `oricf gateway` spins it
    (oricf.gateway.ros.executor); the robot on an executor of its own."""
    gateway = GatewayNode(config, context=context)
    gateway.configure()
    gateway.activate()
    run = Running(gateway)
    executor = make_executor(config.executor_threads, context, config.executor)
    executor.add_node(gateway)
    done = threading.Event()
    spinner = threading.Thread(target=spin_until_shutdown,
                               args=(executor, lambda: not done.is_set() and context.ok()),
                               daemon=True)
    spinner.start()
    try:
        with spinning(context, robot.node):
            try:
                yield run
            finally:
                run.stop()
    finally:
        done.set()
        spinner.join(5)
        executor.shutdown()
        robot.node.destroy_node()
        gateway.destroy_node()


def test_the_loop_publishes_the_policys_action_for_the_robots_state_on_time(
        policy: RunningService, ros_context: Context, hopper_state: np.ndarray) -> None:
    arrays = reference_arrays("HopperBulletEnv_v0")[0]
    expected = np.clip(forward(arrays, hopper_state.astype(np.float32)), -1, 1)
    robot = Robot(ros_context)
    # One action per answer: whatever the link, it comes after its step, so it is played on
    # arrival, asked for while one is still queued, and held for a tick or two of jitter.
    config = control_config(policy.address, late="shift", request_at=1, hold_steps=3)
    with running(config, ros_context, robot) as run:
        source = run.source
        # Before any state arrives: the safe action, and nothing asked.
        first = robot.next_actions(3)
        assert all(list(msg.data) == [0.0, 0.0, 0.0] for msg in first)
        assert source.loop.counts.requests == 0

        robot.publishing = hopper_state.tolist()
        wait_for(lambda: source.loop.counts.answers >= 20)
        robot.drain()
        # The policy's action for that state; the safe action only on a tick whose
        # answer came later than the hold (a loaded machine), never anything else.
        sent = [np.asarray(msg.data) for msg in robot.next_actions(10)]
        policys = [a for a in sent if np.allclose(a, expected, atol=1e-5)]
        assert policys and all(np.allclose(a, expected, atol=1e-5) or not a.any()
                               for a in sent)
        # One action per answer, so every tick asks; each action's observation is
        # measured (its age in steps and in time).
        assert source.loop.ages.seconds.snapshot()[0][-1][1] > 0
        assert source.loop.ages.steps and min(source.loop.ages.steps) >= 0
        # What /metrics and the status say are those counts.
        server = run.gateway.pipeline.metrics_server
        assert server is not None
        metrics = scrape(server.url)
        assert metrics.value("oricf_gateway_control_chunks_total", route="hopper") >= 20
        assert metrics.value("oricf_gateway_control_action_age_seconds_count",
                             route="hopper") > 0
        assert metrics.value("oricf_gateway_control_safe_ticks_total", route="hopper") >= 3
        # The loop's own CPU: its ticks and its 20 requests each took some, and together
        # less than all the time the loop has run (its threads' time, not the process's).
        ticks = metrics.value("oricf_gateway_control_ticks_total", route="hopper")
        cpu_s = [metrics.value("oricf_gateway_control_cpu_seconds_total", route="hopper",
                               work=work) for work in ("tick", "request")]
        assert min(cpu_s) > 0 and sum(cpu_s) < ticks / RATE_HZ
        status = PipelineView(run.gateway.pipeline).status()["control"]["hopper"]
        assert status["answers"] >= 20 and status["action_age_steps_p50"] is not None

        # The robot stops publishing: its state goes stale, the safe action follows.
        missing = source.loop.counts.missing_state
        robot.publishing = None
        wait_for(lambda: source.loop.counts.missing_state > missing + 5)
        robot.wait_steady([0.0, 0.0, 0.0])

        # A state with a value that is not finite: refused, the safe action.
        robot.publishing = [float("nan"), *hopper_state.tolist()[1:]]
        missing = source.loop.counts.missing_state
        wait_for(lambda: source.loop.counts.missing_state > missing + 5)
        robot.wait_steady([0.0, 0.0, 0.0])

        robot.publishing = hopper_state.tolist()
        answers = source.loop.counts.answers
        wait_for(lambda: source.loop.counts.answers > answers + 5)
        run.stop()
        # The last message the robot gets from a stopping gateway is the safe action
        # (the loop's thread has stopped: nothing comes after it).
        got: list[Any] = []

        def last_is_safe() -> bool:
            got.extend(robot.drain())
            return bool(got) and list(got[-1].data) == [0.0, 0.0, 0.0]

        wait_for(last_is_safe)
        assert source.loop.queue.remaining(0) == 0


@pytest.mark.parametrize("executor", ["python", "events"])
def test_ticked_by_the_robots_state_each_state_gets_its_own_action_back(
        policy: RunningService, ros_context: Context, executor: str) -> None:
    """tick: state: the robot's messages are the steps, and the action for each goes out as
    soon as the answer to it comes: a robot that waits for it acts on no old observation.
    The same on rclpy's EventsExecutor (`executor: events`)."""
    arrays = reference_arrays("HopperBulletEnv_v0")[0]
    env = hopper(seed=2)
    state = np.asarray(env.reset(), np.float64)
    robot = Robot(ros_context)
    # No deadman: the test's own pace between states is not the robot's.
    target = {"topic": "/hopper/action", "bounds": [[-1, 1]] * 3}
    config = control_config(policy.address, target, tick="state", late="skip", request_at=0)
    config = config.model_copy(update={"executor": executor})
    with running(config, ros_context, robot) as run:
        source = run.source
        wait_for(lambda: robot.state.get_subscription_count() > 0)
        for _ in range(15):
            robot.state.publish(Float64MultiArray(data=state.tolist()))
            action = np.asarray(robot.next_actions(1)[0].data)
            expected = np.clip(forward(arrays, state.astype(np.float32)), -1, 1)
            np.testing.assert_allclose(action, expected, atol=1e-5)
            state, *_ = env.step(action)
            state = np.asarray(state, np.float64)
        assert source.loop.counts.safe_ticks == 0
        assert list(source.loop.ages.steps) == [0] * 15  # each from its own state


@pytest.mark.parametrize("executor", ["python", "events"])
def test_the_safe_action_goes_out_while_the_policy_is_gone(
        ros_context: Context, hopper_state: np.ndarray, executor: str) -> None:
    stack = ExitStack()
    policy = stack.enter_context(running_service("policy"))
    robot = Robot(ros_context)
    config = control_config(policy.address, safe_action=[0.1, 0.2, 0.3], late="shift",
                            request_at=1)
    config = config.model_copy(update={"executor": executor})
    with stack, running(config, ros_context, robot) as run:
        source = run.source
        robot.publishing = hopper_state.tolist()
        wait_for(lambda: source.loop.counts.answers >= 5)
        stack.close()  # the policy service stops
        wait_for(lambda: source.loop.counts.failed >= 2)
        robot.wait_steady([0.1, 0.2, 0.3])
        assert source.loop.counts.safe_ticks > 0


def test_a_robot_back_from_silence_gets_no_action_queued_before_it(
        ros_context: Context) -> None:
    """tick: state: the loop does not tick while the robot is silent, so the chunk it had
    queued was planned for a robot that has moved on: past max_age_ms of silence it is
    dropped, and the first action after it answers the robot's new state."""
    stack = ExitStack()
    policy = stack.enter_context(running_service("policy", {"model": str(chunk_policy())}))
    robot = Robot(ros_context)
    target = {"topic": "/hopper/action", "bounds": [[-1, 1]] * 4}  # no deadman: the test's pace
    config = control_config(
        policy.address, target, tick="state", late="skip", request_at=0, max_age_ms=1000,
        action_dim=4, state=[{"topic": "/hopper/state", "type": "std_msgs/Float64MultiArray",
                              "size": 39}])
    state = Float64MultiArray(data=[0.1] * 39)
    with stack, running(config, ros_context, robot) as run:
        source = run.source
        wait_for(lambda: robot.state.get_subscription_count() > 0)
        for _ in range(4):  # a chunk of 16 asked for the first state, then played
            robot.state.publish(state)
            robot.next_actions(1)
        assert list(source.loop.ages.steps) == [0, 1, 2, 3]
        assert source.loop.counts.requests == 1
        time.sleep(1.5)  # silent past max_age_ms, 12 actions still queued
        robot.state.publish(state)
        robot.next_actions(1)
        assert source.loop.counts.restarts == 1
        assert source.loop.counts.requests == 2
        assert list(source.loop.ages.steps)[-1] == 0  # from the new state, not the old chunk


def test_an_edge_that_stalls_gets_the_safe_action_out_until_it_answers_again(
        policy: RunningService, ros_context: Context, hopper_state: np.ndarray) -> None:
    host, _, port = policy.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.0)
    robot = Robot(ros_context)
    config = control_config(relay.address, late="shift", request_at=1, hold_steps=2,
                            deadline_steps=5)
    with closing(relay), running(config, ros_context, robot) as run:
        source = run.source
        robot.publishing = hopper_state.tolist()
        wait_for(lambda: source.loop.counts.answers >= 5)
        relay.delay_s = 1.5  # mid-chunk: what is in flight now comes 1.5 s late
        safe = source.loop.counts.safe_ticks
        wait_for(lambda: source.loop.counts.safe_ticks > safe + 20)
        robot.wait_steady([0.0, 0.0, 0.0])
        assert source.loop.counts.expired > 0  # asked again past the deadline
        relay.delay_s = 0.0
        answers = source.loop.counts.answers
        wait_for(lambda: source.loop.counts.answers > answers + 10)
        robot.drain()
        assert any(list(m.data) != [0.0, 0.0, 0.0] for m in robot.next_actions(10))


@pytest.mark.parametrize("tick", ["clock", "state"])
def test_an_edge_that_names_a_step_never_asked_does_not_silence_the_loop(
        ros_context: Context, tick: str) -> None:
    """Its first answer says it answers the request's step + 10**6, its second + 2**40; then
    it answers right: those two are refused, and every answer after them is played."""
    lies = {0: 10**6, 1: 2**40}
    action = [0.5, -0.5, 0.25]
    robot = Robot(ros_context)
    with hostile_edge(lambda call, request: chunk(
            request, [action] * 4, observation=request.step + lies.get(call, 0))) as (
            address, edge):
        config = control_config(address, tick=tick, late="skip", request_at=1, hold_steps=3)
        with running(config, ros_context, robot) as run:
            source = run.source
            robot.publishing = [0.1] * 15
            wait_for(lambda: source.loop.counts.answers >= 10)
            assert source.loop.counts.refused_chunks >= 2 and edge.calls >= 12
            robot.drain()
            assert any(list(m.data) == pytest.approx(action) for m in robot.next_actions(10))


def test_an_action_planted_far_ahead_is_not_played_after_the_edge_goes_silent(
        ros_context: Context) -> None:
    """The edge answers a chunk, then a chunk for 150 steps after its observation (2.5 s at
    this rate, beyond the default max_ahead_ms of one second), then nothing: the loop holds
    the last action, then sends the safe action, and the planted action never goes out."""
    honest, planted = [0.5, -0.5, 0.25], [0.9, 0.9, 0.9]

    def answer(call: int, request: Any) -> Any:
        if call == 0:
            return chunk(request, [honest] * 8)
        if call == 1:
            return chunk(request, [planted] * 14, start=request.step + 150)
        return None  # silent

    robot = Robot(ros_context)
    with hostile_edge(answer) as (address, edge):
        config = control_config(address, late="skip", request_at=0, hold_steps=3)
        with running(config, ros_context, robot) as run:
            loop = run.source.loop
            robot.publishing = [0.1] * 15
            wait_for(lambda: edge.calls >= 2)
            # Ticks are at most steps: past the planted actions' steps and a few more.
            wait_for(lambda: loop.queue.counts.ticks > edge.steps[1] + 150 + 14 + 5, 20)
            sent = [list(m.data) for m in robot.drain()]
    assert all(values != pytest.approx(planted) for values in sent)
    assert any(values == pytest.approx(honest) for values in sent)
    assert sent[-1] == [0.0, 0.0, 0.0] and loop.counts.held_ticks > 0


def test_actions_go_out_as_a_joint_trajectory_within_their_bounds(
        policy: RunningService, ros_context: Context, hopper_state: np.ndarray) -> None:
    target = {"topic": "/hopper/trajectory", "type": "trajectory_msgs/JointTrajectory",
              "joints": ["thigh", "leg", "foot"], "time_from_start_ms": 1500,
              "bounds": [[-0.01, 0.01]] * 3}
    robot = Robot(ros_context, JointTrajectory, "/hopper/trajectory")
    config = control_config(policy.address, target, late="shift", request_at=1)
    with running(config, ros_context, robot) as run:
        source = run.source
        robot.publishing = hopper_state.tolist()
        wait_for(lambda: source.loop.counts.answers >= 5 and source.target.clamped > 0)
        robot.drain()
        msg = robot.next_actions(1)[0]
        assert list(msg.joint_names) == ["thigh", "leg", "foot"]
        (point,) = msg.points
        assert all(abs(v) <= 0.01 for v in point.positions)
        assert (point.time_from_start.sec, point.time_from_start.nanosec) == (1, 500_000_000)


@pytest.mark.parametrize(("change", "message"), [
    ({"safe_action": [0.0, 0.0]}, "safe_action: 2 values for action_dim 3"),
    ({"target": {"topic": "/a", "type": "trajectory_msgs/JointTrajectory", "joints": ["a"]}},
     "target: its joints, fields or bounds give 1 values for action_dim 3"),
    ({"target": {"topic": "/a", "type": "geometry_msgs/Twist", "fields": ["linear.q"]}},
     "fields: geometry_msgs/Twist has no linear.q"),
    ({"target": {"topic": "/a", "type": "std_msgs/Float64MultiArray", "joints": ["a"]}},
     "joints: given with trajectory_msgs/JointTrajectory, and only with it"),
    ({"max_ahead_ms": 5}, "max_ahead_ms: 5 ms is 0 steps at 60.606 Hz: from one step to 4096"),
    ({"max_ahead_ms": 100_000}, "max_ahead_ms: 100000 ms is 6060 steps at 60.606 Hz"),
    ({"max_ahead_ms": 0}, "max_ahead_ms: Input should be greater than 0"),
])
def test_settings_that_cannot_work_are_refused_naming_the_key(change: dict[str, Any],
                                                             message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        control_config("127.0.0.1:1", **change)
    assert "routes.hopper.input.control" in str(caught.value)
    assert message in str(caught.value)
