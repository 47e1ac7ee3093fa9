"""One `oricf demo` run that several tests read: it asks one question about the still
scene, speaks the answer into a PulseAudio sink of its own (recorded) and into a WAV file,
and the sockets its processes hold once the gateway counts are noted. Starting the demo
(every model loads in its own process) costs most of a run, so the answer, the sockets and
the speech are asserted on the same run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.demo.test_demo import STILL_SCENE, demo_deployment
from tests.gateway.sinks.voice import Recorder
from tests.gateway.sources.audio import PulseServer
from tests.launch.helpers import OricfCommand, group_members, private_ros_env
from tests.support.sockets import Socket, inet_sockets

SINK = "oricf_demo_speaker"


@dataclass
class DemoRun:
    folder: Path
    code: int
    command: OricfCommand
    sockets: dict[str, list[Socket]]  # the demo's and each started process group's
    played: np.ndarray  # what the sink played, 16 kHz mono int16
    wav: Path  # --speak-to's file


def held_sockets(command: OricfCommand) -> dict[str, list[Socket]]:
    """Every UDP and TCP socket of the demo and of each process group it started."""
    processes = {"demo": [command.process.pid],
                 **{name: group_members(pids[-1]) for name, pids in command.started().items()}}
    return {name: [s for pid in pids for s in inet_sockets(pid)]
            for name, pids in processes.items()}


def spoken_demo_run(folder: Path) -> DemoRun:
    (folder / "pulse").mkdir()
    pulse = PulseServer(folder / "pulse")
    try:
        pulse.add_sink(SINK)
        pulse.pactl("set-default-sink", SINK)
        recorder = Recorder(pulse, SINK, folder / "played.raw")
        wav = folder / "spoken.wav"
        command = OricfCommand(
            "demo", "--deployment", str(demo_deployment(folder)), "--question",
            "How many people do you see?", *STILL_SCENE, "--speak-to", str(wav),
            "--log", str(folder / "demo.log"),
            env={**private_ros_env(), "PULSE_SERVER": pulse.env()["PULSE_SERVER"]})
        try:
            command.wait_for("the gateway counts people", timeout=600)
            sockets = held_sockets(command)
            code = command.finish(timeout=600)
        finally:
            command.kill()
        played = recorder.samples()
    finally:
        pulse.close()
    return DemoRun(folder, code, command, sockets, played, wav)
