"""The robot's CPU in the placement, measured for real: busy processes (nice 19, so the
detector still gets its share) push the machine's CPU use over the ceiling. The edge is the
detector behind the delay relay (the address, preferred), onboard the same detector directly
(the fallback). While the CPU is over the ceiling an edge over budget keeps its calls; once
the CPU is back under it they move onboard; when it goes over again they leave onboard."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from prometheus_client import generate_latest

from oricf.bench.relay import DelayRelay
from oricf.gateway.endpoints.placement import RobotCpu
from oricf.gateway.metrics import pipeline_registry
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from tests.gateway.endpoints.test_placement import send, wait_for
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService

BUDGET_MS = 1000
CEILING = 0.9
BUSY = "import os\nos.nice(19)\nwhile True:\n    pass\n"


@contextmanager
def busy_cpu() -> Iterator[None]:
    """Two busy processes per core until the block ends."""
    busy = [subprocess.Popen([sys.executable, "-c", BUSY])
            for _ in range(2 * (os.cpu_count() or 1))]
    try:
        yield
    finally:
        for process in busy:
            process.kill()
            process.wait()


def test_robot_cpu_reads_busy_processes() -> None:
    cpu = RobotCpu()
    with busy_cpu():
        cpu.use()
        assert wait_for(lambda: cpu.use() > CEILING, 10)


def test_calls_stay_off_onboard_while_the_robot_cpu_is_over_the_ceiling(
        caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    frame = Frame.from_pixels(video_frames([0])[0])
    host, _, port = detector.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.6)  # the edge: over the budget
    pipeline = Pipeline(pipeline_config(relay.address, {"endpoints": {"detector": {
        "fallback": detector.address, "deadline_ms": 10_000,
        "placement": {"latency_budget_ms": BUDGET_MS, "window": 5, "hysteresis_s": 1.0,
                      "probe_interval_s": 0.5, "onboard": "fallback",
                      "onboard_cpu_ceiling": CEILING}}}}), Outputs())
    endpoint = pipeline.endpoints["detector"]
    placement = endpoint.placement
    assert placement is not None
    pipeline.start()
    try:
        with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"):
            with busy_cpu():
                assert wait_for(lambda: (placement.robot_cpu or 0) > CEILING, 10)
                send(pipeline, frame, 6)  # over budget, but onboard is barred
                assert endpoint.active is endpoint.primary and not placement.decisions
            assert wait_for(lambda: (placement.robot_cpu or 1) <= CEILING, 30)
            send(pipeline, frame, 1)  # over budget, onboard free: calls move there
            assert endpoint.active is endpoint.fallback
            assert placement.decisions == {"over_budget": 1}
            with busy_cpu():
                assert wait_for(lambda: endpoint.active is endpoint.primary, 10)
        assert placement.decisions == {"over_budget": 1, "cpu_over_ceiling": 1}
        assert "calls move to its address: robot CPU" in caplog.text
        assert "over the ceiling of 90%" in caplog.text
        metrics = generate_latest(pipeline_registry(pipeline)).decode()
        assert ('oricf_gateway_endpoint_placements_total{endpoint="detector",'
                'reason="cpu_over_ceiling"} 1.0') in metrics
    finally:
        pipeline.stop()
        relay.close()
