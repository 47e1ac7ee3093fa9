"""End to end over real DDS with the YOLOv8 fall detector added by YAML alone:
configs/pipelines/fall_alert.yaml as shipped, against `oricf serve models`."""

from __future__ import annotations

import cv2
from rclpy.context import Context

from oricf.config import config_dir
from tests.gateway.pipelines import shipped_pipeline
from tests.gateway.ros.gateway_node import running_gateway
from tests.support.data import image
from tests.support.services import RunningService

PIPELINE = config_dir() / "pipelines" / "fall_alert.yaml"


def test_a_fallen_person_is_counted_and_announced(
        ros_context: Context, models: RunningService) -> None:
    standing = cv2.imread(str(image("person.jpg")))
    lying = cv2.rotate(standing, cv2.ROTATE_90_CLOCKWISE)
    config = shipped_pipeline(PIPELINE, models=models.address)
    with running_gateway(config, ros_context) as (gateway, probe):
        seen = []
        for frame in (standing, lying, standing):
            probe.publish_frame(frame)
            seen.append((probe.next("/people_fallen", timeout=10).data,
                         probe.next("/fall_alert", timeout=10).data))
    assert seen[0] == (0, "1 people standing, 0 fallen")
    assert seen[1][0] >= 1 and seen[1][1].startswith("0 people standing")
    assert seen[2] == seen[0]
    reading = gateway.pipeline.products.read("people_fallen")
    assert reading is not None and reading.value == 0
