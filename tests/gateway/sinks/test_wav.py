"""Speech into a WAV file and onto a ROS topic, from the real speech synthesizer."""

from __future__ import annotations

import wave
from pathlib import Path

import numpy as np
from rclpy.serialization import deserialize_message
from std_msgs.msg import Int16MultiArray

from oricf.gateway.ros.messages import to_message
from oricf.gateway.topics.codec import serialize
from oricf.gateway.topics.convert import TOPIC_AUDIO_RATE
from oricf.gateway.values import SpokenAudio
from tests.gateway.sinks.voice import local_gateway
from tests.support.services import RunningService

ANSWER = "I can see 4 people. Two of them are walking to the left."


def test_every_sentence_is_appended_to_one_wav_file(
        tts: RunningService, tmp_path: Path) -> None:
    path = tmp_path / "answers" / "spoken.wav"
    pipeline = {"endpoints": {"tts": {"address": tts.address, "deadline_ms": 30000}},
                "routes": {"say": {"input": {"text": "-"},
                                   "call": {"service": "tts", "method": "Synthesize",
                                            "text": "{text}", "voice": "espeak"},
                                   "outputs": [{"wav": str(path), "from": "speech"}]}}}
    with local_gateway(tmp_path, pipeline) as gateway:
        gateway.say("say", ANSWER)
        gateway.say("say", "Goodbye.")
        assert gateway.pipeline.idle(60)
        with wave.open(str(path)) as partial:  # whole at any moment, before the close
            frames_before_close = partial.getnframes()
    with wave.open(str(path)) as spoken:
        rate, frames, channels = spoken.getframerate(), spoken.getnframes(), spoken.getnchannels()
        samples = np.frombuffer(spoken.readframes(frames), "<i2")
    assert channels == 1 and rate == 22050
    assert frames == frames_before_close and frames / rate > 3  # both answers, all sentences
    assert np.abs(samples.astype(np.int32)).max() > 3000


def test_speech_on_a_topic_is_16_khz_mono_int16() -> None:
    tone = (np.sin(np.arange(22050) / 22050 * 2 * np.pi * 440) * 8000).astype("<i2")
    audio = SpokenAudio(np.repeat(tone, 2).tobytes(), 22050, 2, text="a tone", asked_at=0)
    message = to_message("std_msgs/Int16MultiArray", audio)
    assert len(message.data) == TOPIC_AUDIO_RATE  # one second
    recorded = deserialize_message(serialize("std_msgs/Int16MultiArray", audio),
                                   Int16MultiArray)
    assert list(recorded.data) == list(message.data)
    assert 7000 < np.abs(np.asarray(message.data)).max() < 8500


def test_text_the_synthesizer_refuses_is_counted_and_the_route_goes_on(
        tts: RunningService, tmp_path: Path) -> None:
    path = tmp_path / "spoken.wav"
    pipeline = {"endpoints": {"tts": {"address": tts.address, "deadline_ms": 30000}},
                "routes": {"say": {"input": {"text": "-"},
                                   "call": {"service": "tts", "method": "Synthesize",
                                            "text": "{text}", "voice": "espeak"},
                                   "outputs": [{"wav": str(path), "from": "speech"}]}}}
    with local_gateway(tmp_path, pipeline) as gateway:
        for text in ("ring \x07 the bell", "<speak>hello</speak>", "x" * 100_000, "   "):
            gateway.say("say", text)
        gateway.say("say", ANSWER)
        assert gateway.pipeline.idle(60)
        stats = gateway.pipeline.routes["say"].stats
    assert stats.errors.get("INVALID_ARGUMENT") == 3, stats
    assert stats.skipped == 1 and stats.ok == 1  # nothing to say; then the answer
    with wave.open(str(path)) as spoken:
        assert spoken.getnframes() / spoken.getframerate() > 2
