"""The microphone example's end silence (configs/pipelines/mic_questions.yaml, `vad:`)
against the pauses people make inside a question: a question that pauses at its comma,
spoken slowly by espeak-ng, goes to the recogniser whole, through the real Silero VAD and
the gateway's utterance cutter fed in 32 ms blocks as a microphone delivers them. Cutting
sooner than this silence (what would answer faster) splits it, which the last test shows."""

from __future__ import annotations

import numpy as np
import pytest

from oricf.audio import MODEL_RATE, synthesize
from oricf.config import config_dir
from oricf.gateway.config import load_pipeline
from oricf.gateway.sources.audio import VadConfig
from oricf.gateway.sources.audio_source import Utterances, shared_vad
from tests.support.speech import speech

PIPELINE = config_dir() / "pipelines" / "mic_questions.yaml"
BLOCK = 512
# espeak-ng at 120 words a minute pauses about 350 ms at this comma.
PAUSING = "Tell me, how many people are in the room"
SLOW_WPM = 120


def example_vad() -> VadConfig:
    vad = load_pipeline(PIPELINE).routes["speech"].input.vad
    assert vad is not None
    return vad


def utterances(settings: VadConfig, samples: np.ndarray) -> int:
    cutter = Utterances(shared_vad(), settings)
    cutter.begin(MODEL_RATE)
    audio = np.concatenate([samples, np.zeros(MODEL_RATE, np.int16)])
    count = sum(len(cutter.push(audio[i:i + BLOCK, None])) for i in range(0, len(audio), BLOCK))
    return count + len(cutter.end())


@pytest.fixture(scope="module")
def pausing_question() -> np.ndarray:
    samples = synthesize(PAUSING, rate=SLOW_WPM)
    silence = np.zeros(MODEL_RATE // 5, dtype=np.int16)
    return np.concatenate([silence, samples, silence])


def test_a_question_without_a_pause_is_one_utterance() -> None:
    assert utterances(example_vad(), speech("How many people do you see")) == 1


def test_a_slow_question_that_pauses_at_its_comma_is_one_utterance(
        pausing_question: np.ndarray) -> None:
    assert utterances(example_vad(), pausing_question) == 1


def test_a_shorter_end_silence_would_split_that_question(
        pausing_question: np.ndarray) -> None:
    shorter = example_vad().model_copy(update={"min_silence_ms": 250})
    assert utterances(shorter, pausing_question) == 2
