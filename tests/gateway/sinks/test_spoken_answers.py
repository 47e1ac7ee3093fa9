"""The microphone example (configs/pipelines/mic_questions.yaml) answers aloud, with real
parts: `oricf gateway` on a real PulseAudio server, a question spoken into one null sink
(the microphone), the answer played on another (the speaker) by the real detector, speech
recogniser, language model and speech synthesizer, recorded from that sink's monitor and
transcribed by the speech recogniser."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from oricf.config import config_dir
from tests.gateway.sinks.voice import RATE, Recorder, spoken_words, transcribe, voiced, word_errors
from tests.gateway.sources.audio import PulseServer, gateway
from tests.support.data import video_path
from tests.support.services import RunningService
from tests.support.speech import QUESTION, speech

log = logging.getLogger(__name__)

PIPELINE = config_dir() / "pipelines" / "mic_questions.yaml"
MIC, SPEAKER = "oricf_mic", "oricf_speaker"


@pytest.fixture(scope="module")
def pulse(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PulseServer]:
    server = PulseServer(tmp_path_factory.mktemp("pulse"))
    server.add_sink(MIC)
    server.add_sink(SPEAKER)
    try:
        yield server
    finally:
        server.close()


def test_the_microphone_example_speaks_its_answer(
        pulse: PulseServer, tts: RunningService, detector: RunningService, asr: RunningService,
        llm: RunningService, tmp_path: Path) -> None:
    overlay = tmp_path / "here.yaml"
    overlay.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": detector.address},
                      "asr": {"address": asr.address}, "llm": {"address": llm.address},
                      "tts": {"address": tts.address}},
        "routes": {"speech": {"input": {"audio": f"{MIC}.monitor"}},
                   "voice": {"outputs": [{"audio": {"device": SPEAKER},
                                          "from": "speech"}]},
                   "people": {"input": {"url": str(video_path())}, "outputs": [
                       {"product": "people_count", "from": "count", "max_age_s": 5},
                       {"jsonl": "-", "from": "count"}]}}}))
    with gateway(["--config", str(PIPELINE), "--overlay", str(overlay)],
                 pulse.env()) as running:
        running.wait_log(f"speaker: PulseAudio sink '{SPEAKER}'", 60)
        running.next_line("people", 60)  # the context is there
        pulse.play(MIC, np.zeros(RATE // 2, np.int16))  # an idle sink starts late once
        recorder = Recorder(pulse, SPEAKER, tmp_path / "answer.raw")
        pulse.play(MIC, np.concatenate([speech(QUESTION), np.zeros(RATE, np.int16)]))
        answer = running.next_line("answer", 60)["answer"]
        time.sleep(2 + len(answer.split()) * 0.5)  # spoken by now
        recording = recorder.samples()
        assert running.stop() == 0, running.stderr
    heard = transcribe(asr.channel, recording)
    assert len(voiced(recording)), f"nothing played for {answer!r}:\n{running.stderr}"
    reference = spoken_words(answer)
    errors = word_errors(reference, spoken_words(heard))
    log.info("answer %r heard as %r", answer, heard)
    assert errors / len(reference) <= 0.25, (answer, heard)
