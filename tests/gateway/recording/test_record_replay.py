"""Record and replay: a gateway on real DDS records its topics into MCAP; the recording, or
one written the way rosbag2 writes it, replays through the pipeline without ROS (rclpy
cannot be imported there) to the same counts for the same frames; files that are no MCAP,
cut short, or carry a topic of the wrong type give a clear error, never a traceback."""

from __future__ import annotations

import json
import queue
import re
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer
from rclpy.context import Context
from std_msgs.msg import String

from oricf.audio import synthesize
from oricf.config import config_dir, read_yaml
from oricf.gateway.topics import definitions as msgdefs
from tests.gateway.ros.gateway_node import Probe, running_probe
from tests.support.data import video_frames
from tests.support.processes import oricf_process
from tests.support.services import RunningService

FRAMES = [0, 80, 160, 240, 320, 400, 480, 560]
QUESTION = "How many people do you see?"
FRAME_PERIOD_NS = 100_000_000  # the rosbag2-style recording: a 10 fps camera


@pytest.fixture(scope="module")
def services(detector: RunningService, asr: RunningService, llm: RunningService
             ) -> dict[str, str]:
    return {"detector": detector.address, "asr": asr.address, "llm": llm.address}


def pipeline_file(folder: Path, routes: list[str], services: dict[str, str]) -> Path:
    """people_qa.yaml cut down to these routes, its endpoints at the test services; long
    deadlines, so that a busy test machine never turns into a frame left uncounted."""
    data = read_yaml(config_dir() / "pipelines" / "people_qa.yaml")
    data["routes"] = {name: data["routes"][name] for name in routes}
    used = {data["routes"][name]["call"]["service"] for name in routes}
    data["endpoints"] = {name: {**data["endpoints"][name], "address": services[name],
                                "deadline_ms": 60_000} for name in used}
    data.pop("profiles", None)  # named placements: not needed here
    path = folder / f"pipeline-{'-'.join(routes)}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def gateway_without_ros(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`oricf gateway ARGS` in a process where importing rclpy fails."""
    fake = folder / "no_ros" / "rclpy"
    fake.mkdir(parents=True, exist_ok=True)
    (fake / "__init__.py").write_text("raise ImportError('rclpy must not be imported')\n")
    return subprocess.run(
        [sys.executable, "-m", "oricf", "gateway", *args], capture_output=True, text=True,
        timeout=300, check=False,
        env={"PYTHONPATH": str(fake.parent), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())})


def messages(path: Path) -> list[tuple[str, int, Any]]:
    """(topic, publish_time, decoded message) of every message, read by mcap-ros2-support."""
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        return [(channel.topic, message.publish_time, decoded)
                for _, channel, message, decoded in reader.iter_decoded_messages()]


def on(topic: str, recorded: list[tuple[str, int, Any]]) -> dict[int, Any]:
    """publish_time -> message on one topic (an output's publish_time is its input's)."""
    found = [(stamp, msg) for name, stamp, msg in recorded if name == topic]
    assert len({stamp for stamp, _ in found}) == len(found), f"{topic}: a time twice"
    return dict(found)


def write_rosbag(path: Path, frames: list[np.ndarray], question: str | None = QUESTION,
                 start_ns: int = 1_700_000_000_000_000_000) -> list[int]:
    """An MCAP file as `ros2 bag record -s mcap` writes one: the installed .msg texts joined
    rosbag2's way, frames on /camera/image_raw at 10 fps, then a question on /question and
    a topic no route reads. Returns the frames' publish times."""
    def definition(*types: str) -> str:
        texts = [msgdefs.installed_definition(t) or "" for t in types]
        return "\n".join([texts[0], *(f"{'=' * 80}\nMSG: {t}\n{text}"
                                      for t, text in zip(types[1:], texts[1:], strict=True))])

    stamps = []
    with path.open("wb") as file:
        writer = Writer(file)
        image = writer.register_msgdef("sensor_msgs/msg/Image", definition(
            "sensor_msgs/Image", "std_msgs/Header", "builtin_interfaces/Time"))
        text = writer.register_msgdef("std_msgs/msg/String", definition("std_msgs/String"))
        for i, pixels in enumerate(frames):
            height, width = pixels.shape[:2]
            stamp = start_ns + i * FRAME_PERIOD_NS
            writer.write_message("/camera/image_raw", image, {
                "header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                           "frame_id": "front_camera"},
                "height": height, "width": width, "encoding": "bgr8", "is_bigendian": 0,
                "step": width * 3, "data": pixels.tobytes()},
                log_time=stamp + 2_000_000, publish_time=stamp)
            writer.write_message("/diagnostics_text", text, {"data": f"frame {i}"},
                                 log_time=stamp + 3_000_000)
            stamps.append(stamp)
        if question is not None:
            end = start_ns + len(frames) * FRAME_PERIOD_NS
            writer.write_message("/question", text, {"data": question}, log_time=end)
        writer.finish()
    return stamps


def publish_until_counted(probe: Probe, frame: np.ndarray, stamp_s: int) -> None:
    """A camera frame is best effort: published again until a count comes back."""
    for _ in range(5):
        probe.publish_frame(frame, frame_id="front_camera", stamp_s=stamp_s)
        try:
            probe.next("/human_counter", timeout=5)
            return
        except queue.Empty:
            continue
    raise TimeoutError(f"no count for the frame stamped {stamp_s}")


def test_a_ros_run_is_recorded_and_replays_without_ros_to_the_same_counts(
        services: dict[str, str], ros_context: Context, ros_env: dict[str, str],
        tmp_path: Path) -> None:
    config = pipeline_file(tmp_path, ["people", "typed_question"], services)
    recording, replayed = tmp_path / "run.mcap", tmp_path / "replayed.mcap"
    frames = video_frames(FRAMES)
    with oricf_process("gateway", "--config", str(config), "--record", str(recording),
                       env=ros_env) as gateway, running_probe(ros_context) as probe:
        probe.wait_connected(("camera/image_raw", "/question"), timeout=30)
        probe.warm_up(frames[0])
        for i, frame in enumerate(frames):
            publish_until_counted(probe, frame, 1000 + i)
        probe.question.publish(String(data=QUESTION))
        try:
            probe.next("/answer", timeout=120)
        except queue.Empty:
            gateway.send_signal(signal.SIGTERM)
            gateway.wait(timeout=30)
            assert gateway.stdout is not None
            pytest.fail(f"no answer; the gateway's log:\n{gateway.stdout.read()}")
        gateway.send_signal(signal.SIGTERM)
        assert gateway.wait(timeout=30) == 0
        assert gateway.stdout is not None
        live_log = gateway.stdout.read()
    result = gateway_without_ros(tmp_path, "--config", str(config), "--replay", str(recording),
                                 "--rate", "0", "--record", str(replayed))
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in live_log + result.stderr
    live, again = messages(recording), messages(replayed)
    inputs = on("/camera/image_raw", live)
    counts = {stamp: msg.data for stamp, msg in on("/human_counter", live).items()}
    replay_counts = {stamp: msg.data for stamp, msg in on("/human_counter", again).items()}
    assert len(inputs) >= len(FRAMES)  # the warm-up frames were recorded too
    assert set(counts) <= set(inputs)  # every count points at the frame it counted
    assert replay_counts == {**replay_counts, **counts}  # the same count for the same frame
    assert set(replay_counts) == set(inputs)  # and every frame counted once
    assert all(3 <= count <= 12 for count in replay_counts.values())
    stamps = {a.header.stamp.sec for a in on("/camera/image_annotated", live).values()}
    assert stamps >= {1000 + i for i in range(len(FRAMES))}
    (question, _), = on("/question", live).items()
    assert set(on("/answer", live)) == set(on("/answer", again)) == {question}
    assert [msg.data for msg in on("/question", again).values()] == [QUESTION]


def test_a_rosbag2_recording_replays_through_a_pipeline(services: dict[str, str],
                                                        tmp_path: Path) -> None:
    config = pipeline_file(tmp_path, ["people", "typed_question"], services)
    stamps = write_rosbag(tmp_path / "robot.mcap", video_frames(FRAMES))
    replay = ("--config", str(config), "--replay", str(tmp_path / "robot.mcap"))
    result = gateway_without_ros(tmp_path, *replay, "--rate", "0")
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    counts = [line for line in lines if line["topic"] == "/human_counter"]
    answers = [line for line in lines if line["topic"] == "/answer"]
    assert [line["input_ns"] for line in counts] == stamps  # every frame, in order
    assert all(line["route"] == "people" and 3 <= line["count"] <= 12 for line in counts)
    assert len(answers) == 1 and answers[0]["answer"].strip(), answers
    assert f"{len(FRAMES) + 1} messages played" in result.stderr
    assert f"{len(FRAMES)} of other topics skipped" in result.stderr

    paced = gateway_without_ros(tmp_path, *replay)  # at the recorded pace, as live
    assert paced.returncode == 0, paced.stderr
    played = re.search(r"(\d+) messages played in ([\d.]+) s", paced.stderr)
    assert played is not None and float(played[2]) >= len(FRAMES) * FRAME_PERIOD_NS / 1e9
    counted = [json.loads(line)["input_ns"] for line in paced.stdout.splitlines()
               if '"/human_counter"' in line]
    # a frame that arrives while the detector is busy replaces the waiting one, as live:
    # fewer frames may be counted, but in order, and never the newest dropped
    assert counted == sorted(set(counted)) and set(counted) <= set(stamps)
    assert counted[-1] == stamps[-1]


def test_a_recorded_utterance_is_transcribed_without_ros(services: dict[str, str],
                                                         tmp_path: Path) -> None:
    samples = synthesize(QUESTION)
    path = tmp_path / "speech.mcap"
    with path.open("wb") as file:
        writer = Writer(file)
        audio = writer.register_msgdef("std_msgs/msg/Int16MultiArray",
                                       msgdefs.complete_definition("std_msgs/Int16MultiArray"))
        writer.write_message("/audio/utterance", audio, {
            "layout": {"dim": [{"label": "samples", "size": len(samples), "stride": 1}],
                       "data_offset": 0},
            "data": samples.tolist()}, log_time=5, publish_time=5)
        writer.finish()
    config = pipeline_file(tmp_path, ["speech"], services)
    result = gateway_without_ros(tmp_path, "--config", str(config), "--replay", str(path))
    assert result.returncode == 0, result.stderr
    (line,) = [json.loads(text) for text in result.stdout.splitlines()]
    assert line["topic"] == "/speech/transcript" and line["input_ns"] == 5
    assert "how many people" in line["transcript"].lower()


def wrong_type(path: Path) -> None:
    with path.open("wb") as file:
        writer = Writer(file)
        text = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        writer.write_message("/camera/image_raw", text, {"data": "not a frame"})
        writer.finish()


def cut_in_half(path: Path) -> None:
    write_rosbag(path, video_frames(FRAMES), question=None)
    path.write_bytes(path.read_bytes()[:path.stat().st_size // 2])


BAD_FILES = {
    "random bytes": (lambda p: p.write_bytes(np.random.default_rng(0).bytes(50_000)), 2,
                     "not an MCAP file (it does not start with the MCAP magic bytes)"),
    "empty": (lambda p: p.write_bytes(b""), 2, "the file is empty"),
    "missing": (lambda p: None, 2, "no such file"),
    "a folder": (lambda p: p.mkdir(), 2, "a folder; give the .mcap file in it"),
    "wrong type": (wrong_type, 2, "topic /camera/image_raw is 'std_msgs/String' in the file; "
                                  "route people reads sensor_msgs/Image"),
    "cut short": (cut_in_half, 1, "the recording was cut short; the replay ends here"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_bad_recordings_give_a_clear_error(case: str, services: dict[str, str],
                                           tmp_path: Path) -> None:
    make, code, error = BAD_FILES[case]
    path = tmp_path / "recording.mcap"
    make(path)
    config = pipeline_file(tmp_path, ["people"], services)
    result = gateway_without_ros(tmp_path, "--config", str(config), "--replay", str(path),
                                 "--rate", "0")
    assert result.returncode == code, result.stderr
    assert any(f"{path}: " in line and error in line for line in result.stderr.splitlines())
    assert "Traceback" not in result.stderr
    if case == "cut short":  # what was read before the damage was played
        counts = [json.loads(line)["count"] for line in result.stdout.splitlines()
                  if '"/human_counter"' in line]
        assert 1 <= len(counts) < len(FRAMES)


def test_an_undecodable_message_is_skipped_and_the_rest_plays(services: dict[str, str],
                                                              tmp_path: Path) -> None:
    path = tmp_path / "recording.mcap"
    with path.open("wb") as file:
        writer = McapWriter(file)
        writer.start("ros2", "test")
        schema = writer.register_schema("std_msgs/msg/Int32", "ros2msg", b"int32 data\n")
        channel = writer.register_channel("/question", "cdr", schema)
        writer.add_message(channel, 1, b"\x00\x01", 1)  # two bytes: no CDR header even
        writer.finish()
    config = pipeline_file(tmp_path, ["people", "typed_question"], services)
    result = gateway_without_ros(tmp_path, "--config", str(config), "--replay", str(path))
    assert result.returncode == 2, result.stderr  # the type is checked before anything plays
    assert "topic /question is 'std_msgs/Int32' in the file; route typed_question reads " \
           "std_msgs/String" in result.stderr
    with path.open("wb") as file:
        writer = McapWriter(file)
        writer.start("ros2", "test")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        channel = writer.register_channel("/question", "cdr", schema)
        writer.add_message(channel, 1, b"\x00\x01", 1)
        writer.add_message(channel, 2, b"\x00\x01\x00\x00\x05\x00\x00\x00Four\x00", 2)
        writer.finish()
    result = gateway_without_ros(tmp_path, "--config", str(config), "--replay", str(path),
                                 "--rate", "0")
    assert result.returncode == 0, result.stderr
    assert "a message on /question (std_msgs/String) cannot be decoded" in result.stderr
    assert "no messages on /camera/image_raw (routes people)" in result.stderr
    assert "Traceback" not in result.stderr
    answers = [json.loads(line) for line in result.stdout.splitlines()]
    assert [line["input_ns"] for line in answers] == [2]


def test_recording_flags_refuse_what_cannot_work(services: dict[str, str],
                                                 tmp_path: Path) -> None:
    config = pipeline_file(tmp_path, ["people"], services)
    write_rosbag(tmp_path / "in.mcap", video_frames([0]), question=None)
    (tmp_path / "taken.mcap").write_bytes(b"")
    for args, error in [
            (["--replay", "in.mcap", "--record", "taken.mcap"], "taken.mcap: exists already"),
            (["--rate", "0"], "--rate: only with --replay"),
            (["--replay", "in.mcap", "--rate", "-1"], "must be 0 (as fast as the routes take the "
                                                     "messages) or from 0.01 to 1000")]:
        result = gateway_without_ros(tmp_path, "--config", str(config),
                                     *(str(tmp_path / a) if a.endswith(".mcap") else a
                                       for a in args))
        assert result.returncode == 2, result.stderr
        assert error in result.stderr
        assert "Traceback" not in result.stderr


def test_a_full_disk_stops_the_recording_not_the_writer(tmp_path: Path) -> None:
    """The file size limit of the process stands in for a full disk: a real write error."""
    script = """
import resource, signal, sys
from pathlib import Path
import numpy as np
from oricf.gateway.recording.recorder import Recorder
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # fail the write with EFBIG instead
resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, 2**20))
recorder = Recorder(Path(sys.argv[1]), wait_when_full=True)
for i in range(40):
    recorder.write("/camera/image_raw", "sensor_msgs/Image",
                   np.random.default_rng(i).bytes(100_000), i, i)
recorder.close()
print(recorder.written, recorder.dropped)
"""
    result = subprocess.run([sys.executable, "-c", script, str(tmp_path / "full.mcap")],
                            capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    written, dropped = map(int, result.stdout.split())
    assert written + dropped == 40 and dropped > 0
    assert "full.mcap: cannot write ([Errno 27] File too large): recording stopped" in \
        result.stderr
    assert "Traceback" not in result.stderr
