"""`oricf demo --view`: the demo's gateway serves the live view at the address it prints;
the Foxglove protocol's own client, watching from the start, sees the camera with the
detector's boxes, the transcripts and the answers; Ctrl-C ends the demo normally. (The
demo run is tests/demo/spoken.py's, which the other demo tests read too.)"""

from __future__ import annotations

import re

from tests.demo.spoken import DemoRun


def test_demo_view_shows_the_camera_the_boxes_and_the_answer(spoken_demo: DemoRun) -> None:
    command, got = spoken_demo.command, spoken_demo.viewed
    assert spoken_demo.view_url == f"ws://{spoken_demo.view}"
    assert spoken_demo.code == 0, command.output  # Ctrl-C ended it normally
    assert "1/1 questions answered" in command.output
    answer = re.findall(r"answer     : (.+)", command.output)[-1]
    assert got.topics["/people/image"] == "foxglove.CompressedImage"
    assert got.messages["/people/image"] and got.messages["/people/detections"]
    assert any(a.points for _, a in got.messages["/people/detections"])
    # The viewer connects while the gateway starts; the question comes well after.
    transcripts = [m.message for _, m in got.messages["/speech/transcript"]]
    assert "how many people do you see" in transcripts[-1].lower(), transcripts
    assert answer in [m.message for _, m in got.messages["/spoken_question/answer"]]
