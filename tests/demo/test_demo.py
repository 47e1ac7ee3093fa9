"""`oricf demo` end to end: real services, the real gateway, real DDS, vtest.avi, espeak-ng."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from oricf.bench.rtsp_camera import RtspCamera
from tests.launch.helpers import (
    OricfCommand,
    alive,
    group_members,
    private_ros_env,
    service_entry,
    shipped_pipeline,
    write_deployment,
    write_overlay,
)
from tests.support.data import video_path
from tests.support.processes import free_port
from tests.support.services import RunningService

if TYPE_CHECKING:  # tests/demo/spoken.py imports this module
    from tests.demo.spoken import DemoRun

# vtest.avi's first 10 frames (1 s) show 4 people each. A demo sending only those has one
# count from its first report on, so the count it prints is the one the gateway gave the
# language model, and the answer must state exactly that.
STILL_SCENE = ("--frames", "10")
PEOPLE_IN_STILL_SCENE = 4
NUMBER_WORDS = {word: n for n, word in enumerate([
    "zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
    "eleven", "twelve"])}


def stated_numbers(text: str) -> set[int]:
    """Every number a sentence states, in digits or words ("no one" and "nobody" state 0)."""
    text = re.sub(r"\bno one\b|\bnobody\b", " zero ", text.lower())
    return {int(w) if w.isdigit() else NUMBER_WORDS[w] for w in re.findall(r"\d+|[a-z]+", text)
            if w.isdigit() or w in NUMBER_WORDS}


def reported(output: str) -> tuple[int, str]:
    """The people count and the answer the demo printed."""
    people = re.search(r"people     : (\d+)", output)
    answer = re.search(r"answer     : (.+)", output)
    assert people and answer, output
    return int(people.group(1)), answer.group(1)


def run_demo(*args: str, timeout: float = 600) -> tuple[int, OricfCommand]:
    """`oricf demo ARGS` on a private ROS domain, to its end: (exit code, the command)."""
    command = OricfCommand("demo", *args, env=private_ros_env())
    try:
        return command.finish(timeout=timeout), command
    finally:
        command.kill()


def demo_deployment(folder: Path) -> Path:
    """local.yaml's shape on free ports, so the test never meets another run's services."""
    return write_deployment(folder, {
        "services": {name: service_entry(free_port()) for name in ("detector", "asr", "llm")},
        "gateway": {"config": shipped_pipeline()}})


def test_demo_answers_a_spoken_question_with_the_count(spoken_demo: DemoRun) -> None:
    code, command, tmp_path = spoken_demo.code, spoken_demo.command, spoken_demo.folder
    output = command.output
    assert code == 0, output
    assert "SERVING" in output  # progress while the models load
    transcript = re.search(r"transcript : (.+)", output)
    assert transcript and "how many people" in transcript.group(1).lower(), output
    people, answer = reported(output)
    assert people == PEOPLE_IN_STILL_SCENE, output
    assert stated_numbers(answer) == {people}, output  # the count the demo reported
    assert re.search(r"latency    : ASR \d+ ms \| detector \d+ ms \| LLM \d+ ms \| "
                     r"total \d+ ms", output), output
    assert "1/1 questions answered" in output
    started = command.started()
    assert set(started) == {"detector", "asr", "llm", "tts", "gateway"}  # the demo speaks
    for pids in started.values():
        assert not any(alive(pid) or group_members(pid) for pid in pids), started
    log = (tmp_path / "demo.log").read_text()
    assert "gateway  | " in log and "detector | " in log


def test_demo_keeps_every_socket_on_this_machine(spoken_demo: DemoRun) -> None:
    """Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, as private_ros_env sets it: once the
    gateway counts, every UDP and TCP socket of the demo's processes (its own DDS
    participant, the gateway's, the services', speech synthesis included) is bound to a
    loopback address, as `ss -tuanp` would show them."""
    sockets = spoken_demo.sockets
    assert spoken_demo.code == 0, spoken_demo.command.output
    assert set(sockets) == {"demo", "detector", "asr", "llm", "tts", "gateway"}
    for name in ("demo", "gateway"):  # DDS participants: discovery on 127.0.0.1
        assert any(s.table == "udp" and str(s.address) == "127.0.0.1"
                   for s in sockets[name]), sockets[name]
    for name, held in sockets.items():
        assert all(s.loopback for s in held), f"{name}: {[str(s) for s in held]}"


@pytest.mark.long
def test_demo_takes_its_camera_from_an_rtsp_stream(tmp_path: Path) -> None:
    with RtspCamera() as camera:
        camera.play_file(video_path())
        code, command = run_demo("--deployment", str(demo_deployment(tmp_path)),
                                 "--source", camera.url, "--question",
                                 "How many people do you see?")
    output = command.output
    assert code == 0, output
    assert f"camera {camera.url}" in output
    people, _ = reported(output)
    assert 1 <= people <= 15, output
    assert "1/1 questions answered" in output


def test_demo_refuses_a_deployment_without_gateway(tmp_path: Path) -> None:
    path = write_deployment(tmp_path, {"services": {"detector": service_entry(free_port())}})
    code, command = run_demo("--deployment", str(path), timeout=120)
    assert code == 1
    assert "the demo needs a deployment with a gateway" in command.output
    assert command.started() == {}


def test_demo_refuses_zero_frames() -> None:
    command = OricfCommand("demo", "--frames", "0")
    assert command.finish(timeout=60) == 2
    assert "--frames must be at least 1" in command.output


def test_demo_with_the_services_on_an_edge(tmp_path: Path, detector: RunningService,
                                            asr: RunningService, llm: RunningService) -> None:
    """--placement edge's path: nothing started but the gateway, which calls remote
    services (real ones, in this test's process, standing in for compose/edge.yaml)."""
    placement = write_overlay(tmp_path, {"detector": {"address": detector.address},
                                         "asr": {"address": asr.address},
                                         "llm": {"address": llm.address}})
    path = write_deployment(tmp_path, {
        "remote": ["detector", "asr", "llm"],
        "gateway": {"config": shipped_pipeline(), "overlays": [str(placement)]}})
    code, command = run_demo("--deployment", str(path), "--question",
                             "How many people are there?", *STILL_SCENE, "--no-speak")
    assert code == 0, command.output
    assert set(command.started()) == {"gateway"}  # --no-speak: no speech synthesis either
    assert "spoken     :" not in command.output
    assert f"llm SERVING at {llm.address}" in command.output
    people, answer = reported(command.output)
    assert people == PEOPLE_IN_STILL_SCENE
    assert stated_numbers(answer) == {people}, command.output
    assert "1/1 questions answered" in command.output
