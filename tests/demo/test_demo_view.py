"""`oricf demo --view`: the demo's gateway serves the live view at the address it prints;
the Foxglove protocol's own client, watching from the start, sees the camera with the
detector's boxes, the transcripts and the answers; Ctrl-C ends the demo normally."""

from __future__ import annotations

import re
import signal
import socket
import time
from pathlib import Path

from tests.demo.test_demo import demo_deployment
from tests.gateway.live_view.viewers import watching
from tests.launch.helpers import OricfCommand, private_ros_env
from tests.support.processes import free_port


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


def test_demo_view_shows_the_camera_the_boxes_and_the_answer(tmp_path: Path) -> None:
    port = free_port()
    command = OricfCommand("demo", "--deployment", str(demo_deployment(tmp_path)),
                           "--question", "How many people do you see?",
                           "--question", "How many people are there?", "--view",
                           f"127.0.0.1:{port}", "--log", str(tmp_path / "demo.log"),
                           env=private_ros_env())
    try:
        url = command.wait_for(r"live view: (ws://\S+)", timeout=60).group(1)
        assert url == f"ws://127.0.0.1:{port}"
        wait_listening(port, command)
        with watching(url) as received:
            command.wait_for(r"stays open at ws://", timeout=600)
            time.sleep(2)  # frames go on after the questions
        command.process.send_signal(signal.SIGINT)
        code = command.finish(timeout=120)
    finally:
        command.kill()
    assert code == 0, command.output
    assert "2/2 questions answered" in command.output
    answer = re.findall(r"answer     : (.+)", command.output)[-1]
    got = received[0]
    assert got.topics["/people/image"] == "foxglove.CompressedImage"
    assert got.messages["/people/image"] and got.messages["/people/detections"]
    assert any(a.points for _, a in got.messages["/people/detections"])
    # The viewer connects while the gateway starts; the last question comes well after.
    transcripts = [m.message for _, m in got.messages["/speech/transcript"]]
    assert "how many people are there" in transcripts[-1].lower(), transcripts
    assert answer in [m.message for _, m in got.messages["/spoken_question/answer"]]
