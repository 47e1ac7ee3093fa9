"""Audio devices as route inputs, with real parts: a PulseAudio null sink's monitor is the
microphone, espeak-ng speaks questions into the sink, and the real ASR, LLM and detector
services answer them through configs/pipelines/mic_questions.yaml. Also a device that
vanishes and comes back, and one that does not exist."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from oricf.config import config_dir
from tests.gateway.sources.audio import PulseServer, gateway
from tests.support.data import video_path
from tests.support.services import RunningService
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words

log = logging.getLogger(__name__)

PIPELINE = config_dir() / "pipelines" / "mic_questions.yaml"
SINK = "oricf_test"
SILENCE = np.zeros(16000, dtype=np.int16)


@pytest.fixture(scope="module")
def pulse(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PulseServer]:
    server = PulseServer(tmp_path_factory.mktemp("pulse"))
    server.add_sink(SINK)
    try:
        yield server
    finally:
        server.close()


def speech_only(tmp_path: Path, asr: str, device: str, **audio: int) -> Path:
    """A pipeline of the example's speech route alone: device -> Transcribe -> JSON lines."""
    pipeline = yaml.safe_load(PIPELINE.read_text())
    speech_route = pipeline["routes"]["speech"]
    speech_route["input"].update(audio=device, **audio)
    speech_route["outputs"] = [{"jsonl": "-", "from": "transcript"}]
    path = tmp_path / "speech.yaml"
    endpoint = {"address": asr, "deadline_ms": 10000}
    path.write_text(yaml.safe_dump({"endpoints": {"asr": endpoint},
                                    "routes": {"speech": speech_route}}))
    return path


def test_spoken_questions_from_a_microphone_are_transcribed_and_answered(
        pulse: PulseServer, tmp_path: Path, detector: RunningService, asr: RunningService,
        llm: RunningService) -> None:
    overlay = tmp_path / "here.yaml"
    overlay.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": detector.address},
                      "asr": {"address": asr.address}, "llm": {"address": llm.address}},
        "routes": {"speech": {"input": {"audio": f"{SINK}.monitor"}},
                   "people": {"input": {"url": str(video_path())}, "outputs": [
                       {"product": "people_count", "from": "count", "max_age_s": 5},
                       {"jsonl": "-", "from": "count"}]}}}))
    with gateway(["--config", str(PIPELINE), "--overlay", str(overlay)],
                 pulse.env()) as running:
        running.wait_log(f"capturing from PulseAudio source '{SINK}.monitor'", 60)
        count = running.next_line("people", 60)["count"]  # the context is there
        pulse.play(SINK, SILENCE[:8000])  # an idle null sink's first playback starts late
        question = speech(QUESTION)
        voiced_until = np.nonzero(np.abs(question) > 300)[0][-1] / 16000
        spoken_end = pulse.play(SINK, np.concatenate([question, SILENCE])) + voiced_until
        heard = running.next_line("speech", 60)
        answer = running.next_line("answer", 60)
        assert running.stop() == 0, running.stderr
    assert set(QUESTION_WORDS) <= set(words(heard["transcript"])), heard
    assert answer["answer"].strip(), answer
    assert 1 <= count <= 15
    log.info("end of speech -> transcript %.2f s, -> answer %.2f s: %r",
             heard["time"] - spoken_end, answer["time"] - spoken_end, answer["answer"])


def test_a_device_that_vanishes_is_reopened_and_heard_again(pulse: PulseServer,
                                                           tmp_path: Path,
                                                           asr: RunningService) -> None:
    """Captured as 48 kHz stereo: mixed down and resampled to 16 kHz on the way."""
    module = pulse.add_sink("oricf_gone")
    config = speech_only(tmp_path, asr.address, "oricf_gone.monitor", sample_rate=48000,
                         channels=2)
    with gateway(["--config", str(config)], pulse.env()) as running:
        first = running.wait_log("capturing from PulseAudio source 'oricf_gone.monitor' "
                                 "(through PortAudio 'pulse') at 48000 Hz, 2 channel(s), "
                                 "resampled to 16000 Hz", 60)
        pulse.remove(module)
        lost = running.wait_log("is gone; reopening", 30, after=first)
        running.wait_log("trying again in", 30, after=lost)  # retried with backoff
        pulse.add_sink("oricf_gone")
        running.wait_log("capturing from PulseAudio source 'oricf_gone.monitor'", 60,
                         after=lost)
        pulse.play("oricf_gone", np.concatenate([speech(QUESTION), SILENCE]))
        heard = running.next_line("speech", 60)
        assert running.stop() == 0, running.stderr
    assert set(QUESTION_WORDS) <= set(words(heard["transcript"])), running.stderr


def test_a_device_that_does_not_exist_stops_the_gateway_at_start_naming_the_devices(
        pulse: PulseServer, tmp_path: Path) -> None:
    config = speech_only(tmp_path, "127.0.0.1:1", "no_such_microphone")
    with gateway(["--config", str(config)], pulse.env()) as running:
        assert running.process.wait(timeout=60) == 2
    assert "routes.speech.input.audio: no audio input device 'no_such_microphone'" \
        in running.stderr
    assert "PortAudio input devices: 0 'pulse'" in running.stderr
    assert f"PulseAudio sources: {SINK}.monitor" in running.stderr
    assert "Traceback" not in running.stderr

