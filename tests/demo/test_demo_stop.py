"""Ctrl-C (SIGINT) and SIGTERM stop `oricf demo` at every stage, and everything it started
stops with it; a demo killed outright (SIGKILL) leaves nothing running either, because its
children follow it (oricf.lifeline). Real services, gateway and DDS."""

from __future__ import annotations

import signal
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.demo.test_demo import demo_deployment
from tests.launch.helpers import OricfCommand, alive, group_members, private_ros_env

STOP_S = 60  # the demo stops its gateway and services, each within stop_grace_s


def everything_gone(command: OricfCommand, timeout: float = STOP_S) -> list[int]:
    """Waits until no process the demo started (nor any in their groups) runs; returns
    what still runs at the deadline."""
    pids = [pid for pids in command.started().values() for pid in pids]
    assert pids, command.output
    deadline = time.monotonic() + timeout
    while True:
        left = [p for p in pids if alive(p) or group_members(p)]
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.2)


def when_line(pattern: str) -> Callable[[OricfCommand, Path], None]:
    return lambda command, _folder: command.wait_for(pattern, timeout=300) and None


def when_speaking(command: OricfCommand, folder: Path) -> None:
    """The first answer's speech has begun to arrive (--speak-to's file holds samples)."""
    wav = folder / "spoken.wav"
    deadline = time.monotonic() + 300
    while not (wav.exists() and wav.stat().st_size > 1000):
        assert command.process.poll() is None, command.output
        assert time.monotonic() < deadline, command.output
        time.sleep(0.05)


# stage -> (when it has begun, the signal sent then)
STAGES = {
    "starting the services": (when_line(r"started llm \(pid"), signal.SIGTERM),
    "waiting for the gateway": (when_line(r"started gateway \(pid"), signal.SIGINT),
    "asking": (when_line(r"asking the questions"), signal.SIGTERM),
    "speaking": (when_speaking, signal.SIGINT),
}


# Asking the questions (between the gateway's start and the first spoken answer) is the long
# run's: the default run stops the demo in the three stages around it.
@pytest.mark.parametrize("stage", [
    pytest.param(stage, marks=[pytest.mark.long] if stage == "asking" else [])
    for stage in STAGES])
def test_a_signal_stops_the_demo_and_everything_it_started(tmp_path: Path, stage: str) -> None:
    began, signum = STAGES[stage]
    command = OricfCommand("demo", "--deployment", str(demo_deployment(tmp_path)),
                           "--question", "How many people do you see?",
                           "--speak-to", str(tmp_path / "spoken.wav"),
                           "--log", str(tmp_path / "demo.log"), env=private_ros_env())
    try:
        began(command, tmp_path)
        command.process.send_signal(signum)
        code = command.finish(timeout=STOP_S)
        left = everything_gone(command)
    finally:
        command.kill()
    assert code == 130, command.output
    assert "demo interrupted" in command.output
    assert f"received {signum.name}: stopping" in command.output
    assert "Traceback" not in command.output, command.output
    assert left == [], command.output
    assert "gateway stopped" in command.output or stage == "starting the services"


def test_children_of_a_killed_demo_stop_by_themselves(tmp_path: Path) -> None:
    command = OricfCommand("demo", "--deployment", str(demo_deployment(tmp_path)),
                           "--question", "How many people do you see?", "--no-speak",
                           "--log", str(tmp_path / "demo.log"), env=private_ros_env())
    try:
        command.wait_for(r"started gateway \(pid", timeout=300)
        command.process.kill()  # no clean-up of its own: the children notice it is gone
        command.finish(timeout=10)
        left = everything_gone(command)
    finally:
        command.kill()
    assert set(command.started()) == {"detector", "asr", "llm", "gateway"}
    assert left == [], command.output
