"""One `oricf demo` run that several tests read: it asks one question about the still
scene, speaks the answer into a PulseAudio sink of its own (recorded) and into a WAV file,
and serves the live view (`--view`), which the Foxglove protocol's own client watches from
the gateway's start until Ctrl-C ends the demo; the sockets its processes hold once the
gateway counts are noted. Starting the demo (every model loads in its own process) costs
most of a run, so the answer, the sockets, the speech and the view are asserted on the same
run."""

from __future__ import annotations

import signal
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.demo.test_demo import STILL_SCENE, demo_deployment
from tests.gateway.live_view.viewers import Received, watching
from tests.gateway.sinks.voice import Recorder
from tests.gateway.sources.audio import PulseServer
from tests.launch.helpers import OricfCommand, group_members, private_ros_env
from tests.support.processes import free_port
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
    view: str  # --view's address
    view_url: str  # the live view's address, as the demo printed it
    viewed: Received  # what the live view's client got


def held_sockets(command: OricfCommand) -> dict[str, list[Socket]]:
    """Every UDP and TCP socket of the demo and of each process group it started."""
    processes = {"demo": [command.process.pid],
                 **{name: group_members(pids[-1]) for name, pids in command.started().items()}}
    return {name: [s for pid in pids for s in inet_sockets(pid)]
            for name, pids in processes.items()}


def wait_listening(port: int, command: OricfCommand, timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            assert command.process.poll() is None, command.output
            assert time.monotonic() < deadline, command.output
            time.sleep(0.2)


def spoken_demo_run(folder: Path) -> DemoRun:
    (folder / "pulse").mkdir()
    pulse = PulseServer(folder / "pulse")
    port = free_port()
    try:
        pulse.add_sink(SINK)
        pulse.pactl("set-default-sink", SINK)
        recorder = Recorder(pulse, SINK, folder / "played.raw")
        wav = folder / "spoken.wav"
        command = OricfCommand(
            "demo", "--deployment", str(demo_deployment(folder)), "--question",
            "How many people do you see?", *STILL_SCENE, "--speak-to", str(wav),
            "--view", f"127.0.0.1:{port}", "--log", str(folder / "demo.log"),
            env={**private_ros_env(), "PULSE_SERVER": pulse.env()["PULSE_SERVER"]})
        try:
            url, sockets, viewed = viewed_run(command, port)
            code = command.finish(timeout=120)
        finally:
            command.kill()
        played = recorder.samples()
    finally:
        pulse.close()
    return DemoRun(folder, code, command, sockets, played, wav, f"127.0.0.1:{port}", url,
                   viewed)


def viewed_run(command: OricfCommand, port: int
               ) -> tuple[str, dict[str, list[Socket]], Received]:
    """The demo watched from the gateway's start to Ctrl-C; the address it printed, the
    sockets held once the gateway counted and what the viewer got. The viewer is started
    before the live view listens, so it is subscribed before the question can be asked
    (under load, a viewer started afterwards could miss the one transcript)."""
    with watching(f"ws://127.0.0.1:{port}", early=True) as received:
        url = command.wait_for(r"live view: (ws://\S+)", timeout=60).group(1)
        wait_listening(port, command)
        command.wait_for("the gateway counts people", timeout=600)
        sockets = held_sockets(command)
        command.wait_for(r"stays open at ws://", timeout=600)
        time.sleep(2)  # frames go on after the questions
    command.process.send_signal(signal.SIGINT)
    return url, sockets, received[0]
