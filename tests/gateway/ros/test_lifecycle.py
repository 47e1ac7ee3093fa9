"""`oricf gateway` as a managed node, driven as `ros2 lifecycle get/set` and launch's lifecycle
events drive it: through its lifecycle_msgs services over real DDS (PyPI's ROS has no
`ros2` command). A control route stands for the outputs: the policy's actions reach the
robot only while the node is active, and each deactivate ends them with the safe action."""

from __future__ import annotations

import queue
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import yaml
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray

from tests.gateway.ros.gateway_node import spinning, wait_for
from tests.support.processes import oricf_process
from tests.support.services import RunningService

NODE = "lifecycle_gateway"
SAFE = [0.0, 0.0, 0.0]
EXECUTORS = {"python": "SingleThreadedExecutor", "events": "EventsExecutor"}
CALL_S = 30.0  # a transition builds or stops the whole gateway: generous on a busy machine


def control_pipeline(path: Path, policy: str, executor: str = "python") -> Path:
    """One control route: the robot's state in, the policy's action out at 30 Hz (one
    action per answer, asked a step ahead and held a few ticks: tests/gateway/sources)."""
    control = {"rate_hz": 30, "action_dim": 3, "max_age_ms": 500, "late": "shift",
               "request_at": 1, "hold_steps": 3,
               "state": [{"topic": "/lc/state", "type": "std_msgs/Float64MultiArray",
                          "size": 15}],
               "target": {"topic": "/lc/action", "bounds": [[-1, 1]] * 3}}
    path.write_text(yaml.safe_dump({
        "node_name": NODE, "executor": executor,
        "endpoints": {"hopper": {"address": policy, "deadline_ms": 2000}},
        "routes": {"hopper": {"input": {"control": control},
                              "call": {"method": "Act", "service": "hopper"}}}}))
    return path


class Robot:
    """The robot's node: publishes its state on a timer, collects the actions it gets, and
    asks the gateway's lifecycle services as `ros2 lifecycle` does."""

    def __init__(self, context: Context, state: np.ndarray) -> None:
        self.node = Node("lifecycle_test_robot", context=context)
        self.actions: queue.Queue[list[float]] = queue.Queue()
        self.states_sent = 0
        self._state = self.node.create_publisher(Float64MultiArray, "/lc/state",
                                                 QoSProfile(depth=1))
        self.node.create_subscription(Float64MultiArray, "/lc/action",
                                      lambda msg: self.actions.put(list(msg.data)), 50)
        self.node.create_timer(1 / 30, lambda: self._publish(state))
        self._get = self.node.create_client(GetState, f"/{NODE}/get_state")
        self._change = self.node.create_client(ChangeState, f"/{NODE}/change_state")

    def _publish(self, state: np.ndarray) -> None:
        self._state.publish(Float64MultiArray(data=state.tolist()))
        self.states_sent += 1

    def state(self) -> str:
        assert self._get.wait_for_service(timeout_sec=CALL_S), "no get_state service"
        response = self._get.call(GetState.Request(), timeout_sec=CALL_S)
        assert response is not None
        return str(response.current_state.label)

    def change(self, transition: int) -> bool:
        assert self._change.wait_for_service(timeout_sec=CALL_S), "no change_state service"
        request = ChangeState.Request()
        request.transition.id = transition
        response = self._change.call(request, timeout_sec=CALL_S)
        assert response is not None
        return bool(response.success)

    def drain(self) -> list[list[float]]:
        got = []
        while not self.actions.empty():
            got.append(self.actions.get_nowait())
        return got

    def wait_policy_action(self) -> None:
        """Until an action that is the policy's (not the safe one) arrives."""
        wait_for(lambda: any(a != pytest.approx(SAFE) for a in self.drain()), timeout=CALL_S)

    def wait_safe_then_nothing(self) -> None:
        """The last action is the safe one, and while the robot sends ten more states (a
        third of a second of ticks) no action follows it."""
        got: list[list[float]] = []

        def last_is_safe() -> bool:
            got.extend(self.drain())
            return bool(got) and got[-1] == pytest.approx(SAFE)

        wait_for(last_is_safe, timeout=CALL_S)
        self.assert_silent()

    def assert_silent(self, states: int = 10) -> None:
        sent = self.states_sent
        wait_for(lambda: self.states_sent >= sent + states)
        assert self.drain() == []


@contextmanager
def robot_beside(context: Context, state: np.ndarray) -> Iterator[Robot]:
    robot = Robot(context, state)
    try:
        with spinning(context, robot.node):
            yield robot
    finally:
        robot.node.destroy_node()


@pytest.mark.parametrize("executor", ["python", "events"])
def test_a_lifecycle_manager_configures_activates_deactivates_and_shuts_the_gateway_down(
        policy: RunningService, ros_context: Context, ros_env: dict[str, str],
        hopper_state: np.ndarray, tmp_path: Path, executor: str) -> None:
    """--lifecycle managed: unconfigured until told; no action while inactive; actions
    while active; the safe action and then nothing on deactivate, twice; cleanup, shutdown,
    and the process ends by itself. On either ROS executor."""
    config = control_pipeline(tmp_path / "control.yaml", policy.address, executor)
    with oricf_process("gateway", "--config", str(config), "--lifecycle", "managed",
                       env=ros_env) as gateway, robot_beside(ros_context, hopper_state) as robot:
        assert robot.state() == "unconfigured"
        assert robot.change(Transition.TRANSITION_CONFIGURE)
        assert robot.state() == "inactive"
        wait_for(lambda: robot.node.count_publishers("/lc/action") > 0, timeout=CALL_S)
        robot.assert_silent()  # configured, its publisher there, nothing sent

        for _ in range(2):  # activated again after a deactivate: built anew
            assert robot.change(Transition.TRANSITION_ACTIVATE)
            assert robot.state() == "active"
            robot.wait_policy_action()
            assert robot.change(Transition.TRANSITION_DEACTIVATE)
            assert robot.state() == "inactive"
            robot.wait_safe_then_nothing()

        assert robot.change(Transition.TRANSITION_CLEANUP)
        assert robot.state() == "unconfigured"
        assert robot.change(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
        assert gateway.wait(timeout=CALL_S) == 0  # finalized: the process ends
        assert gateway.stdout is not None
        log = gateway.stdout.read()
    assert "unconfigured, for its lifecycle manager" in log
    assert f"ROS executor: {EXECUTORS[executor]}" in log
    assert "Traceback" not in log


def test_the_plain_start_configures_and_activates_itself(
        policy: RunningService, ros_context: Context, ros_env: dict[str, str],
        hopper_state: np.ndarray, tmp_path: Path) -> None:
    """Without --lifecycle: active at once, as before; a lifecycle manager can still stop it
    (deactivate: the safe action, then nothing), and SIGTERM ends it."""
    config = control_pipeline(tmp_path / "control.yaml", policy.address)
    with oricf_process("gateway", "--config", str(config), env=ros_env) as gateway, \
            robot_beside(ros_context, hopper_state) as robot:
        robot.wait_policy_action()
        assert robot.state() == "active"
        assert robot.change(Transition.TRANSITION_DEACTIVATE)
        robot.wait_safe_then_nothing()
        gateway.send_signal(signal.SIGTERM)
        assert gateway.wait(timeout=CALL_S) == 0


def test_a_pipeline_without_ros_has_no_node_to_manage() -> None:
    with oricf_process("gateway", "--config", "people_video", "--lifecycle",
                       "managed") as gateway:
        assert gateway.wait(timeout=60) == 2
        assert gateway.stdout is not None
        assert "--lifecycle managed: only for a ROS node" in gateway.stdout.read()
