"""End to end over real DDS with a declared model: camera frames -> Infer on `oricf serve
models` -> /human_counter, as configs/pipelines/people_declared.yaml ships it."""

from __future__ import annotations

from rclpy.context import Context

from oricf.config import config_dir
from tests.gateway.pipelines import shipped_pipeline
from tests.gateway.ros.gateway_node import running_gateway
from tests.support.data import video_frames
from tests.support.services import RunningService

PIPELINE = config_dir() / "pipelines" / "people_declared.yaml"
FRAMES = [0, 80, 160, 400]


def test_the_declared_pipeline_counts_people_on_a_topic(
        ros_context: Context, models: RunningService) -> None:
    config = shipped_pipeline(PIPELINE, models=models.address)
    with running_gateway(config, ros_context) as (gateway, probe):
        counts = []
        for frame in video_frames(FRAMES):
            probe.publish_frame(frame)
            counts.append(probe.next("/human_counter", timeout=10).data)
    assert counts[0] == 4 and all(3 <= c <= 12 for c in counts), counts
    assert gateway.pipeline.routes["people"].stats.ok == len(FRAMES)
