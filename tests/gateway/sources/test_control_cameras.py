"""A control loop whose policy sees, over real DDS: the robot publishes its state and its
camera's images (sensor_msgs/Image or CompressedImage), the loop sends the newest image of
each camera with the state to the policy service, and the action is what the model made of
that image (tests/support/camera_policy.py: the image's channel means, then the state). A
camera that stops, or sends what is not an image, leaves the robot with the safe action."""

from __future__ import annotations

import queue
from typing import Any

import cv2
import numpy as np
import pytest
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Float64MultiArray

from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, parse_pipeline
from oricf.gateway.control.source import ControlSource
from tests.gateway.ros.gateway_node import wait_for
from tests.gateway.sources.test_control import running
from tests.support.camera_policy import CAMERA
from tests.support.services import RunningService

STATE = [0.25, -1.5]
SAFE = [0.0] * 5


def camera_config(address: str, image_type: str, **settings: Any) -> PipelineConfig:
    control = {"rate_hz": 50, "action_dim": 5, "max_age_ms": 300, "tick": "state",
               "state": [{"topic": "/arm/state", "type": "std_msgs/Float64MultiArray",
                          "size": 2}],
               "images": [{"name": CAMERA, "topic": "/arm/top/image", "type": image_type}],
               "target": {"topic": "/arm/action", "bounds": [[-10, 10]] * 5}} | settings
    return parse_pipeline({
        "endpoints": {"arm": {"address": address, "deadline_ms": 2000}},
        "routes": {"arm": {"input": {"control": control},
                           "call": {"method": "Act", "service": "arm"}}}},
        "test camera control pipeline")


class CameraRobot:
    """Publishes a state and an image when told; collects every action it is sent."""

    def __init__(self, context: Context, image_type: str) -> None:
        self.node = Node("camera_test_robot", context=context)
        self.actions: queue.Queue[Any] = queue.Queue()
        self.state = self.node.create_publisher(Float64MultiArray, "/arm/state",
                                                QoSProfile(depth=1))
        self.compressed = image_type == "sensor_msgs/CompressedImage"
        self.camera = self.node.create_publisher(
            CompressedImage if self.compressed else Image, "/arm/top/image", QoSProfile(depth=1))
        self.node.create_subscription(Float64MultiArray, "/arm/action", self.actions.put, 50)

    def see(self, pixels: np.ndarray) -> bytes:
        """Publishes the image; the bytes it carries."""
        if self.compressed:
            ok, data = cv2.imencode(".png", pixels)
            assert ok
            self.camera.publish(CompressedImage(format="png", data=data.tobytes()))
            return data.tobytes()
        height, width = pixels.shape[:2]
        self.camera.publish(Image(height=height, width=width, encoding="bgr8",
                                  step=width * 3, data=pixels.tobytes()))
        return pixels.tobytes()

    def act_on(self, source: ControlSource | None = None, pixels: np.ndarray | None = None,
               *, wait_s: float = 10.0) -> list[float]:
        """Sends the image (None: none) and, once the loop has it, the state: the action
        the robot is sent for them."""
        if pixels is not None and source is not None:
            data = self.see(pixels)
            wait_for(lambda: getattr(source.observation.newest_image(0), "data", b"") == data)
        self.state.publish(Float64MultiArray(data=STATE))
        return list(self.actions.get(timeout=wait_s).data)


def colour(blue: int, green: int, red: int) -> np.ndarray:
    pixels = np.zeros((24, 32, 3), np.uint8)
    pixels[...] = (blue, green, red)
    return pixels


@pytest.mark.parametrize("image_type", ["sensor_msgs/Image", "sensor_msgs/CompressedImage"])
def test_the_action_answers_the_newest_image_of_the_camera_with_the_state(
        camera_policy: RunningService, ros_context: Context, image_type: str) -> None:
    robot = CameraRobot(ros_context, image_type)
    with running(camera_config(camera_policy.address, image_type), ros_context, robot) as run:
        source = run.source
        wait_for(lambda: robot.camera.get_subscription_count() > 0
                 and robot.state.get_subscription_count() > 0)
        # No image yet: nothing is asked, the safe action goes out.
        assert robot.act_on() == SAFE and source.loop.counts.requests == 0
        seen = [np.round(robot.act_on(source, pixels), 2).tolist()
                for pixels in (colour(0, 0, 255), colour(255, 0, 0), colour(0, 255, 0))]
        assert seen == [[1.0, 0.0, 0.0, *STATE], [0.0, 0.0, 1.0, *STATE],
                        [0.0, 1.0, 0.0, *STATE]]


def test_a_camera_that_stops_or_lies_leaves_the_robot_with_the_safe_action(
        camera_policy: RunningService, ros_context: Context) -> None:
    robot = CameraRobot(ros_context, "sensor_msgs/Image")
    config = camera_config(camera_policy.address, "sensor_msgs/Image", max_age_ms=150)
    with running(config, ros_context, robot) as run:
        source = run.source
        wait_for(lambda: robot.camera.get_subscription_count() > 0)
        red = colour(0, 0, 255)
        assert robot.act_on(source, red)[0] == pytest.approx(1.0)
        # The camera stops: past max_age_ms its last image is too old to act on.
        wait_for(lambda: robot.act_on() == SAFE)
        # An image whose header lies about its size is refused, not sent on.
        refused = source.observation.refused
        robot.camera.publish(Image(height=24, width=32, encoding="bgr8", step=96,
                                   data=bytes(10)))
        wait_for(lambda: source.observation.refused > refused)
        assert source.observation.newest_image(0) is None
        assert robot.act_on() == SAFE
        assert robot.act_on(source, red)[0] == pytest.approx(1.0)  # a good image: on it goes


def test_two_cameras_under_one_name_are_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError) as caught:
        camera_config("127.0.0.1:1", "sensor_msgs/Image",
                      images=[{"name": "top", "topic": "/a"}, {"name": "top", "topic": "/b"}])
    assert "routes.arm.input.control" in str(caught.value)
    assert "images: a camera is named twice (top, top)" in str(caught.value)
