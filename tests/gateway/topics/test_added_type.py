"""A ROS message type is one entry of the table of types: registered here alone, a type the
gateway never knew is read by the ROS node and written by it over real DDS (a control loop's
state and actions, against the session's Hopper policy), and written into a recording that
any MCAP reader decodes back to the same values, with no other change."""

from __future__ import annotations

import queue
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float32MultiArray

from oricf.gateway.recording.recorder import Recorder
from oricf.gateway.topics.convert import Action, Fields
from oricf.gateway.topics.types import RosType, register, unregister
from tests.gateway.ros.gateway_node import wait_for
from tests.gateway.sources.test_control import Robot, control_config, running
from tests.support.pybullet_sim import forward, reference_arrays
from tests.support.services import RunningService

NAME = "std_msgs/Float32MultiArray"


def floats(value: object, header: object) -> Fields:
    values = value.values if isinstance(value, Action) else value
    return {"data": [float(v) for v in values]}  # type: ignore[attr-defined]


FLOAT32_ARRAY = RosType(NAME, "MultiArrayLayout layout\nfloat32[] data\n",
                        frozenset({"state", "action"}),
                        read=lambda msg: np.asarray(msg.data, np.float64), write=floats)


@pytest.fixture
def float32_array() -> Iterator[None]:
    register(FLOAT32_ARRAY)
    yield
    unregister(NAME)


class Float32Robot(Robot):
    """The robot's side in the new type: its state published, its actions collected."""

    def __init__(self, context: Context) -> None:
        self.node = Node("added_type_robot", context=context)
        self.actions: queue.Queue[Float32MultiArray] = queue.Queue()
        self.state = self.node.create_publisher(Float32MultiArray, "/hopper/state",
                                                QoSProfile(depth=1))
        self.node.create_subscription(Float32MultiArray, "/hopper/action", self.actions.put, 50)
        self.publishing: list[float] | None = None
        self.node.create_timer(1 / 60, self._publish)

    def _publish(self) -> None:
        if self.publishing is not None:
            self.state.publish(Float32MultiArray(data=self.publishing))


@pytest.mark.usefixtures("float32_array")
def test_a_type_registered_alone_is_read_and_written_by_the_node(
        policy: RunningService, ros_context: Context, hopper_state: np.ndarray) -> None:
    state32 = hopper_state.astype(np.float32)
    expected = np.clip(forward(reference_arrays("HopperBulletEnv_v0")[0], state32), -1, 1)
    config = control_config(
        policy.address, target={"topic": "/hopper/action", "type": NAME,
                                "bounds": [[-1, 1]] * 3},
        state=[{"topic": "/hopper/state", "type": NAME, "size": 15}],
        late="shift", request_at=1, hold_steps=3)
    robot = Float32Robot(ros_context)
    with running(config, ros_context, robot) as run:
        robot.publishing = state32.tolist()
        wait_for(lambda: run.source.loop.counts.answers >= 5, timeout=30)
        robot.drain()
        sent = [np.asarray(msg.data) for msg in robot.next_actions(10)]
        assert any(np.allclose(a, expected, atol=1e-5) for a in sent), sent


@pytest.mark.usefixtures("float32_array")
def test_a_type_registered_alone_is_recorded_and_read_back(tmp_path: Path) -> None:
    path = tmp_path / "added.mcap"
    recorder = Recorder(path)
    values = [0.5, -1.25, 3.0]
    recorder.output("/hopper/action", NAME, Action(values), {})
    recorder.close()
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        [(schema, channel, _, decoded)] = list(reader.iter_decoded_messages())
    assert (schema.name, channel.topic) == ("std_msgs/msg/Float32MultiArray", "/hopper/action")
    assert FLOAT32_ARRAY.value(decoded).tolist() == values
