"""The robot's battery in the placement, over real DDS: a sensor_msgs/BatteryState publisher
(reliable, as battery drivers publish) on the placement's battery_topic. Onboard is the
detector directly (the address, preferred), the edge the same detector behind the delay
relay (the fallback). Under battery_low calls leave onboard; back above it they return once
the probes find onboard within budget for the hysteresis time; an unknown charge (NaN) is
ignored."""

from __future__ import annotations

import logging
import math
import time

import pytest
from rclpy.context import Context
from sensor_msgs.msg import BatteryState

from oricf.bench.relay import DelayRelay
from tests.gateway.ros.gateway_node import logged, running_gateway, wait_for
from tests.gateway.test_pipeline import pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService


def battery(charge: float) -> BatteryState:
    msg = BatteryState()
    msg.percentage = charge
    return msg


def test_a_low_battery_moves_calls_off_onboard_and_back(
        ros_context: Context, caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    frame = video_frames([0])[0]
    host, _, port = detector.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.0)
    config = pipeline_config(detector.address, {"endpoints": {"detector": {
        "fallback": relay.address, "deadline_ms": 10_000,
        "placement": {"latency_budget_ms": 1000, "window": 5, "hysteresis_s": 1.0,
                      "probe_interval_s": 0.2, "onboard": "address",
                      "battery_topic": "/battery_state", "battery_low": 0.2}}}})
    assert config.uses_ros
    try:
        with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"), \
                running_gateway(config, ros_context) as (gateway, probe):
            endpoint = gateway.pipeline.endpoints["detector"]
            placement = endpoint.placement
            assert placement is not None
            publisher = probe.node.create_publisher(BatteryState, "/battery_state", 10)
            wait_for(lambda: publisher.get_subscription_count() > 0)
            probe.warm_up(frame)
            publisher.publish(battery(0.9))
            wait_for(lambda: placement.battery == pytest.approx(0.9))
            assert endpoint.active is endpoint.primary and not placement.decisions

            publisher.publish(battery(0.1))
            wait_for(lambda: endpoint.active is endpoint.fallback)
            assert placement.decisions == {"battery_low": 1}
            wait_for(logged(caplog, "calls move to its fallback: battery at 10%, under 20%"))
            on_edge = endpoint.answered["fallback"]
            probe.publish_frame(frame)
            assert probe.next("/human_counter", timeout=10).data == 4
            assert endpoint.answered["fallback"] == on_edge + 1

            # Unknown: the last charge stands, so calls stay off onboard past the
            # hysteresis time (were NaN taken as a charge, nothing would bar onboard).
            publisher.publish(battery(math.nan))
            time.sleep(3)
            assert endpoint.active is endpoint.fallback
            assert placement.battery == pytest.approx(0.1)
            publisher.publish(battery(0.6))
            wait_for(lambda: endpoint.active is endpoint.primary, timeout=30)
            assert placement.decisions == {"battery_low": 1, "back_within_budget": 1}
    finally:
        relay.close()
