"""Over real DDS: bad messages are logged and dropped; a dead detector is failed over."""

from __future__ import annotations

import logging
from contextlib import ExitStack

import pytest
from rclpy.context import Context
from sensor_msgs.msg import Image
from std_msgs.msg import Int16MultiArray

from tests.gateway.pipelines import people_qa
from tests.gateway.ros.gateway_node import Probe, logged, running_gateway, wait_for
from tests.support.data import video_frames
from tests.support.processes import free_port
from tests.support.services import RunningService, running_service


def bad_image(encoding: str, width: int, height: int, size: int) -> Image:
    msg = Image(encoding=encoding, width=width, height=height, step=width * 3)
    msg.data = bytes(size)
    return msg


BAD_IMAGES = [
    (bad_image("yuv422", 768, 576, 768 * 576 * 2), "unsupported image encoding 'yuv422'"),
    (bad_image("bgr8", 0, 0, 0), "width and height must be > 0"),
    (bad_image("bgr8", 768, 576, 1000), "needs 1,327,104 bytes, got 1,000"),
]


def count_one_frame(probe: Probe) -> int:
    probe.drain("/human_counter")
    probe.publish_frame(video_frames([0])[0])
    return int(probe.next("/human_counter", timeout=10).data)


def test_bad_messages_are_logged_and_the_gateway_keeps_working(
        ros_context: Context, caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    caplog.set_level(logging.INFO)
    with running_gateway(people_qa(detector=detector.address), ros_context) as (gw, probe):
        for msg, message in BAD_IMAGES:
            probe.camera.publish(msg)
            wait_for(logged(caplog, message))
            assert count_one_frame(probe) == 4
        probe.audio.publish(Int16MultiArray())  # an utterance without samples
        wait_for(logged(caplog, "audio message carries no samples"))
        assert count_one_frame(probe) == 4
    assert gw.pipeline.routes["people"].stats.bad_input == 3
    assert gw.pipeline.routes["speech"].stats.bad_input == 1


def test_counts_go_through_the_fallback_and_return_to_the_primary(
        ros_context: Context, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    port = free_port()
    primary_listen = {"server": {"listen": f"127.0.0.1:{port}"}}
    with running_service("detector") as fallback, ExitStack() as primary_stack:
        primary_stack.enter_context(running_service("detector", primary_listen))
        overlay = {"endpoints": {"detector": {"fallback": fallback.address,
                                              "probe_interval_s": 0.2}}}
        config = people_qa(overlay, detector=f"127.0.0.1:{port}")
        with running_gateway(config, ros_context) as (gw, probe):
            endpoint = gw.pipeline.endpoints["detector"]
            assert count_one_frame(probe) == 4
            assert endpoint.active is endpoint.primary

            primary_stack.close()  # the primary detector goes away mid-run
            counts = [count_one_frame(probe) for _ in range(3)]
            assert counts == [4, 4, 4]
            assert endpoint.active is endpoint.fallback and endpoint.failovers == 1
            assert logged(caplog, "using fallback")()

            with running_service("detector", primary_listen):  # restarted on the same port
                wait_for(lambda: endpoint.active is endpoint.primary, timeout=15)
                assert endpoint.recoveries == 1
                assert count_one_frame(probe) == 4
                fallback.host.stop(grace=0)  # now only the primary can answer
                assert [count_one_frame(probe) for _ in range(2)] == [4, 4]
                assert endpoint.failovers == 1
