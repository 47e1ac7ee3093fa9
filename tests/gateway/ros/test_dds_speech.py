"""Spoken and typed questions over real DDS, answered by the real ASR and language model
with the current people count as context."""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from rclpy.context import Context
from std_msgs.msg import String

from oricf.audio import synthesize
from oricf.gateway.shells.ros_node import GatewayNode
from tests.gateway.pipelines import people_qa
from tests.gateway.ros.gateway_node import Probe, logged, running_gateway, wait_for
from tests.support.data import video_frames
from tests.support.services import RunningService

QUESTION = "How many people do you see?"
# people_count goes stale after 2 s here, so the stale case needs no long wait.
FAST_STALE = {"routes": {"people": {"outputs": [
    {"topic": "/human_counter", "type": "std_msgs/Int32", "from": "count"},
    {"product": "people_count", "from": "count", "max_age_s": 2}]}}}


@pytest.fixture(scope="module")
def services(detector: RunningService, asr: RunningService, llm: RunningService
             ) -> dict[str, str]:
    return {"detector": detector.address, "asr": asr.address, "llm": llm.address}


@contextmanager
def camera_feed(probe: Probe, frame: np.ndarray, fps: float = 4.0) -> Iterator[None]:
    """Keeps publishing the frame, as a camera does, so the count stays current."""
    stop = threading.Event()

    def feed() -> None:
        while not stop.wait(1 / fps):
            probe.publish_frame(frame)

    thread = threading.Thread(target=feed, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


@contextmanager
def gateway(services: dict[str, str], context: Context) -> Iterator[tuple[GatewayNode, Probe]]:
    with running_gateway(people_qa(FAST_STALE, **services), context) as (node, probe):
        yield node, probe


def test_spoken_question_is_answered_with_the_current_count(
        services: dict[str, str], ros_context: Context) -> None:
    speech = synthesize(QUESTION)
    with gateway(services, ros_context) as (node, probe), \
            camera_feed(probe, video_frames([0])[0]):
        assert probe.next("/human_counter", timeout=10).data == 4
        probe.publish_audio(speech)
        transcript = probe.next("/speech/transcript", timeout=30).data
        answer = probe.next("/answer", timeout=60).data
    assert "how many people" in transcript.lower()
    assert "4" in answer, answer
    assert node.pipeline.routes["spoken_question"].stats.ok == 1


def test_typed_question_and_a_stale_count(services: dict[str, str],
                                          ros_context: Context) -> None:
    with gateway(services, ros_context) as (node, probe):
        with camera_feed(probe, video_frames([0])[0]):
            assert probe.next("/human_counter", timeout=10).data == 4
            probe.question.publish(String(data=QUESTION))
            current = probe.next("/answer", timeout=60).data
        wait_for(lambda: node.pipeline.products.read("people_count").stale, timeout=10)
        probe.question.publish(String(data=QUESTION))
        stale = probe.next("/answer", timeout=60).data
    assert "4" in current, current
    assert "4" not in stale and "know" in stale.lower(), stale  # never a stale count as current


def test_garbage_audio_is_logged_and_speech_keeps_working(
        services: dict[str, str], ros_context: Context, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    rng = np.random.default_rng(0)
    with gateway(services, ros_context) as (node, probe):
        probe.publish_audio(np.zeros(0, np.int16))
        wait_for(logged(caplog, "audio message carries no samples"))
        probe.publish_audio(rng.integers(-3000, 3000, 16000 * 40).astype(np.int16))  # 40 s
        wait_for(logged(caplog, "Transcribe call to asr"), timeout=30)
        probe.publish_audio(rng.integers(-20000, 20000, 16000).astype(np.int16))  # 1 s of noise
        wait_for(lambda: node.pipeline.workers["speech"].stats.handled == 3, timeout=30)
        probe.drain("/speech/transcript")
        probe.publish_audio(synthesize(QUESTION))
        transcript = probe.next("/speech/transcript", timeout=30).data
    stats = node.pipeline.routes["speech"].stats
    assert stats.bad_input == 1 and stats.errors.get("INVALID_ARGUMENT") == 1
    assert "how many people" in transcript.lower()


def test_counts_keep_coming_while_the_language_model_works(
        services: dict[str, str], ros_context: Context) -> None:
    frame = video_frames([0])[0]
    with gateway(services, ros_context) as (node, probe):
        probe.publish_frame(frame)
        assert probe.next("/human_counter", timeout=10).data == 4
        asking = node.pipeline.workers["typed_question"]
        probe.question.publish(String(data=QUESTION))
        wait_for(lambda: asking.busy, timeout=10)
        probe.publish_frame(frame)
        during = probe.next("/human_counter", timeout=10).data
        still_generating = asking.busy
        answer = probe.next("/answer", timeout=60).data
    # Counted while the language model was generating: the people route does not wait for
    # it. How long a count takes is `oricf bench gateway`'s figure.
    assert during == 4 and still_generating
    assert "4" in answer
