"""A learned policy on the edge, the robot acting on time, in real time over ROS 2: the
simulator as a robot (`python -m oricf.bench.sim_node`: a metaworld arm task at 80 Hz,
its observation published, the newest action taken), the gateway's control loop in its own
process (`oricf gateway`), and the chunk policy behaviour-cloned from metaworld's expert
served by `oricf serve policy` on an edge host (a network namespace) behind the delay relay
(a 50 ms round trip). The arm closes the drawer: the task's own success."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from oricf.bench.link import oricf, served
from oricf.bench.netns import edge_host
from oricf.bench.relay import DelayRelay
from tests.gateway.ros.gateway_node import private_domain
from tests.support.chunk_policy import TASK, chunk_policy

POLICY_PORT = 50055
SEED = 3


def control_pipeline(address: str) -> dict[str, Any]:
    return {
        "endpoints": {"arm": {"address": address, "deadline_ms": 1000}},
        "routes": {"arm": {
            "input": {"control": {
                "rate_hz": 80, "action_dim": 4, "max_age_ms": 100,
                "state": [{"topic": "/sim/state", "type": "std_msgs/Float64MultiArray",
                           "size": 39}],
                "late": "skip", "merge": "latest", "request_at": 8, "deadline_steps": 16,
                "hold_steps": 4,
                "target": {"topic": "/sim/action", "bounds": [[-1, 1]] * 4,
                           "deadman_ms": 200}}},
            "call": {"method": "Act", "service": "arm"}}}}


@pytest.fixture
def edge_policy(tmp_path: Path) -> Iterator[str]:
    declaration = chunk_policy()
    config = tmp_path / "policy.yaml"
    with edge_host() as edge:
        address = f"{edge.address}:{POLICY_PORT}"
        config.write_text(yaml.safe_dump({"server": {"listen": address},
                                          "model": str(declaration)}))
        with served(edge.exec_argv(oricf("serve", "policy", "--config", str(config))),
                    address):
            host, _, port = address.rpartition(":")
            relay = DelayRelay((host, int(port)), delay_s=0.025)  # each way
            try:
                yield relay.address
            finally:
                relay.close()


def test_the_arm_closes_the_drawer_with_its_policy_on_the_edge_50_ms_away(
        edge_policy: str, tmp_path: Path) -> None:
    env = {**os.environ, **private_domain()}
    pipeline = tmp_path / "control.yaml"
    pipeline.write_text(yaml.safe_dump(control_pipeline(edge_policy)))
    gateway = subprocess.Popen(oricf("gateway", "--config", str(pipeline)), env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        robot = subprocess.run(
            [sys.executable, "-m", "oricf.bench.sim_node", "--sim", TASK, "--seed", str(SEED),
             "--wait-s", "60"], env=env, capture_output=True, text=True, timeout=180)
    finally:
        gateway.terminate()
        _, log = gateway.communicate(timeout=30)
    assert robot.returncode == 0, robot.stderr[-3000:]
    result = json.loads(robot.stdout.strip().splitlines()[-1])
    print(result)
    assert result["success"], (result, log[-3000:])
    assert result["actions_received"] >= result["steps"] * 0.9, result
    assert gateway.returncode == 0, log[-3000:]
