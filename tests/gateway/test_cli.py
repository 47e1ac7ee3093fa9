"""`oricf gateway` as its own process: overlay on the command line, real DDS, clean stop."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
import yaml
from rclpy.context import Context

from tests.gateway.pipelines import PEOPLE_QA
from tests.gateway.ros.gateway_node import running_probe, wait_for
from tests.support.data import video_frames
from tests.support.processes import free_port, oricf_process
from tests.support.services import RunningService


def test_gateway_process_counts_people_and_stops_on_sigterm(
        ros_context: Context, ros_env: dict[str, str], tmp_path: Path,
        detector: RunningService) -> None:
    overlay = tmp_path / "here.yaml"
    frames = video_frames([0, 400])
    overlay.write_text(yaml.safe_dump({"endpoints": {"detector": {
        "address": detector.address}}}))
    with oricf_process("gateway", "--config", str(PEOPLE_QA), "--overlay", str(overlay),
                       "--ros-args", "-r", "__node:=gateway_under_test",
                       env=ros_env) as gateway, running_probe(ros_context) as probe:
        probe.wait_connected(timeout=30)
        wait_for(lambda: "gateway_under_test" in probe.node.get_node_names())
        probe.warm_up(frames[1])
        counts = []
        for frame in frames:
            probe.publish_frame(frame)
            counts.append(probe.next("/human_counter", timeout=10).data)
        gateway.send_signal(signal.SIGTERM)
        assert gateway.wait(timeout=15) == 0
        assert gateway.stdout is not None
        log = gateway.stdout.read()
    assert counts == [4, 4]
    assert f"endpoint detector: {detector.address}" in log
    assert re.search(r"route people: (\d+) received, 0 dropped as stale, \1 ok", log)


def test_gateway_process_stops_cleanly_while_frames_stream(
        ros_context: Context, ros_env: dict[str, str], tmp_path: Path,
        detector: RunningService) -> None:
    """SIGTERM lands while the camera thread is mid-frame and the executor is spinning."""
    overlay = tmp_path / "here.yaml"
    frame = video_frames([0])[0]
    overlay.write_text(yaml.safe_dump({"endpoints": {"detector": {
        "address": detector.address}}}))
    with running_probe(ros_context) as probe:
        for _ in range(2):
            with oricf_process("gateway", "--config", str(PEOPLE_QA), "--overlay",
                               str(overlay), env=ros_env) as gateway:
                probe.wait_connected(timeout=30)
                probe.warm_up(frame)
                stop_publishing = threading.Event()

                def stream(stop: threading.Event) -> None:
                    while not stop.wait(0.03):
                        probe.publish_frame(frame)

                publisher = threading.Thread(target=stream, args=(stop_publishing,),
                                             daemon=True)
                publisher.start()
                try:
                    wait_for(lambda: probe.next("/human_counter", timeout=5).data == 4)
                    gateway.send_signal(signal.SIGTERM)
                    code = gateway.wait(timeout=15)
                finally:
                    stop_publishing.set()
                    publisher.join()
                assert gateway.stdout is not None
                log = gateway.stdout.read()
            assert code == 0, log
            assert "Traceback" not in log
            assert re.search(r"route people: \d+ received, \d+ dropped as stale", log)


# `oricf gateway`, with a SIGTERM sent to itself while its node is being built (once the node
# has its subscriptions, before it starts anything), and a moment for a signal thread to act
# on it (rclpy's shut the context down under the node being built; the gateway's own only
# asks it to stop once built).
SIGTERM_WHILE_STARTING = """
import os, signal, sys, time
from oricf.gateway.shells.ros_node import GatewayNode
subscribe = GatewayNode._subscribe_batteries
def stop_now(self):
    subscribe(self)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(1.0)
GatewayNode._subscribe_batteries = stop_now
from oricf.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_sigterm_while_the_gateway_starts_stops_it_cleanly(
        ros_env: dict[str, str]) -> None:
    done = subprocess.run(
        [sys.executable, "-c", SIGTERM_WHILE_STARTING, "gateway", "--config", str(PEOPLE_QA),
         "--set", 'endpoints.detector.address="127.0.0.1:1"'],
        env={**os.environ, **ros_env}, capture_output=True, text=True, timeout=60)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log
    assert "gateway stopped while starting" in log
    assert "Traceback" not in log and "Exception in thread" not in log, log


def test_gateway_process_refuses_a_bad_config(tmp_path: Path) -> None:
    overlay = tmp_path / "bad.yaml"
    overlay.write_text("endpoints: {detector: {deadline_ms: -1}}\n")
    with oricf_process("gateway", "--config", str(PEOPLE_QA), "--overlay",
                       str(overlay)) as gateway:
        assert gateway.wait(timeout=30) == 2
        assert gateway.stdout is not None
        assert "endpoints.detector.deadline_ms: Input should be greater than 0" in \
            gateway.stdout.read()


@pytest.mark.parametrize("executor", ["python", "events"])
def test_a_stopped_gateway_sends_the_zero_command_before_ros_goes(
        ros_env: dict[str, str], tmp_path: Path, executor: str) -> None:
    """A command of 0.2 m/s through the control API, then SIGTERM 100 ms later: the robot's
    driver (a plain rclpy subscriber) hears the command, then the zero command, and the
    gateway exits 0. The deadman (10 s) is far off: only the stop can send that zero. On
    either ROS executor."""
    from tests.gateway.agents.scene import TWIST_TOPIC, ros_listener

    port = free_port()
    (tmp_path / "tokens").write_text("stop-test-token\n")
    overlay = tmp_path / "agent.yaml"
    overlay.write_text(yaml.safe_dump({
        "executor": executor,
        "endpoints": {"detector": {"address": "127.0.0.1:1"}},
        "control": {"listen": f"127.0.0.1:{port}", "auth": {"file": str(tmp_path / "tokens")}},
        "agent": {"audit": str(tmp_path / "audit.jsonl"), "targets": {"cmd_vel": {
            "topic": TWIST_TOPIC, "type": "geometry_msgs/Twist",
            "bounds": {"linear.x": [-0.3, 0.3]}, "deadman_ms": 10000}}}}))
    headers = {"Authorization": "Bearer stop-test-token"}
    url = f"http://127.0.0.1:{port}/v1/publish"
    with ros_listener() as driver, oricf_process(
            "gateway", "--config", str(PEOPLE_QA), "--overlay", str(overlay),
            env=ros_env) as gateway:
        # Zero commands until one arrives: the control API is up and discovery complete.
        deadline = time.monotonic() + 60
        while driver.twists.empty():
            assert gateway.poll() is None and time.monotonic() < deadline
            with contextlib.suppress(httpx.TransportError):  # not listening yet
                httpx.post(url, json={"target": "cmd_vel", "message": {}}, headers=headers,
                           timeout=5)
            time.sleep(0.6)
        time.sleep(0.6)  # the policy's rate
        driver.drain()
        answer = httpx.post(url, json={"target": "cmd_vel",
                                       "message": {"linear": {"x": 0.2}}},
                            headers=headers, timeout=5)
        assert answer.status_code == 200, answer.text
        time.sleep(0.1)
        gateway.send_signal(signal.SIGTERM)
        code = gateway.wait(timeout=30)
        assert gateway.stdout is not None
        log = gateway.stdout.read()
        moving = driver.twists.get(timeout=10)
        stopped = driver.twists.get(timeout=10)
    assert code == 0, log
    assert "Traceback" not in log, log
    expected = {"python": "SingleThreadedExecutor", "events": "EventsExecutor"}[executor]
    assert f"ROS executor: {expected}" in log, log
    assert moving.linear.x == 0.2
    assert (stopped.linear.x, stopped.angular.z) == (0.0, 0.0)


def test_the_events_executor_on_an_rclpy_without_it_is_refused_before_ros_starts(
        tmp_path: Path) -> None:
    """executor: events on an rclpy that lacks the EventsExecutor (Humble's: its import
    fails, as here) stops the gateway at once, saying what it needs."""
    overlay = tmp_path / "events.yaml"
    overlay.write_text("executor: events\n")
    humble_like = ("import sys; sys.modules['rclpy.experimental'] = None; "
                   "from oricf.cli import main; sys.exit(main())")
    done = subprocess.run(
        [sys.executable, "-c", humble_like, "gateway", "--config", str(PEOPLE_QA),
         "--overlay", str(overlay)], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "executor: events needs rclpy's EventsExecutor (Jazzy's rclpy 7.1.4 or later" in \
        done.stdout + done.stderr
    assert "gateway stopping" not in done.stdout + done.stderr  # ROS never started
