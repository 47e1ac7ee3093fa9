"""The gateway without ROS as an Arm robot runs it: in the emulated arm64 root, it reads
vtest.avi, has the detector (in the root too) count the people, and writes a JSON line per
frame (configs/pipelines/people_video.yaml)."""

from __future__ import annotations

import json
import queue
import threading
from typing import IO, Any

import pytest

from tests.arm64.conftest import ServiceInRoot
from tests.arm64.root import ORICF, root_process
from tests.support.waiting import wait_for

pytestmark = pytest.mark.arm64
LINES = 3
# A frame's answer under emulation: the pipeline's 1 s deadline is an onboard CPU's.
DEADLINE_MS = 120_000


def read_lines(stream: IO[str], into: queue.Queue[dict[str, Any]]) -> None:
    for line in stream:
        if line.startswith("{"):
            into.put(json.loads(line))


def test_the_gateway_counts_people_from_the_video_to_json_lines(
        arm64_detector: ServiceInRoot) -> None:
    address = arm64_detector.address
    with root_process(ORICF, "gateway", "--config", "configs/pipelines/people_video.yaml",
                      "--set", f"endpoints.detector.address={address}",
                      "--set", f"endpoints.detector.deadline_ms={DEADLINE_MS}",
                      stdout=True) as gateway:
        assert gateway.stdout is not None
        lines: queue.Queue[dict[str, Any]] = queue.Queue()
        threading.Thread(target=read_lines, args=(gateway.stdout, lines), daemon=True).start()
        wait_for(lambda: lines.qsize() >= LINES or gateway.poll() is not None, timeout=1800,
                 what=f"{LINES} JSON lines from the gateway in the arm64 root")
        assert gateway.poll() is None, "the gateway ended before its lines"
    answers = [lines.get_nowait() for _ in range(LINES)]
    assert {answer["route"] for answer in answers} == {"people"}
    # vtest.avi shows a street with a handful of pedestrians in every frame.
    assert all(2 <= answer["count"] <= 12 for answer in answers), answers
