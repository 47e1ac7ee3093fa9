"""Helpers for the speech-output tests: a pipeline run in this process on a real PulseAudio
server, a recorder of a sink's monitor, transcription by the real speech recogniser, and
the word error rate."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import grpc
import numpy as np
import yaml

from bench.common import stop
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sources.audio_source import AudioSource
from oricf.services.tts.text import say_numbers
from oricf.v1 import speech_pb2, speech_pb2_grpc
from tests.gateway.sources.audio import PulseServer
from tests.support.speech import words

RATE = 16000


class Recorder:
    """parecord of a sink's monitor into raw 16 kHz mono int16."""

    def __init__(self, pulse: PulseServer, sink: str, path: Path) -> None:
        self.path = path
        self.process = subprocess.Popen(
            ["parecord", f"--device={sink}.monitor", "--raw", "--format=s16le",
             f"--rate={RATE}", "--channels=1", "--latency-msec=20", str(path)],
            env=pulse.env())
        time.sleep(0.5)  # connected before anything plays

    def samples(self) -> np.ndarray:
        time.sleep(0.5)  # the tail of the playback reaches the file
        stop(self.process, timeout=10)
        return np.frombuffer(self.path.read_bytes(), "<i2")


def voiced(samples: np.ndarray, level: int = 300) -> np.ndarray:
    """Indices of samples louder than `level`."""
    return np.nonzero(np.abs(samples.astype(np.int32)) > level)[0]


def transcribe(asr: grpc.Channel, samples: np.ndarray) -> str:
    audio = speech_pb2.Audio(data=samples.astype("<i2").tobytes(), encoding="pcm_s16le",
                             sample_rate=RATE, channels=1)
    reply = speech_pb2_grpc.SpeechRecognizerStub(asr).Transcribe(
        speech_pb2.TranscribeRequest(audio=audio, language="en"), timeout=60)
    return str(reply.text)


def spoken_words(text: str) -> list[str]:
    """Words as said: numbers in words ("4" and "four" are the same word)."""
    return words(say_numbers(text).replace("-", " "))


def word_errors(reference: list[str], heard: list[str]) -> int:
    """Substitutions, insertions and deletions between two word lists (Levenshtein)."""
    row = list(range(len(heard) + 1))
    for i, ref in enumerate(reference, 1):
        previous, row[0] = row[0], i
        for j, word in enumerate(heard, 1):
            previous, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1,
                                           previous + (ref != word))
    return row[-1]


@dataclass
class LocalGateway:
    """A pipeline in this process: its outlets (speakers), and the audio sources started."""

    config: PipelineConfig
    pipeline: Pipeline
    outlets: Outlets
    sources: list[AudioSource]

    def say(self, route: str, text: str) -> None:
        self.pipeline.submit(route, lambda: {"text": text})

    def speaker(self) -> Any:
        return next(iter(self.outlets.speakers.values()))


@contextmanager
def local_gateway(tmp_path: Path, pipeline: dict[str, Any]) -> Iterator[LocalGateway]:
    """Loads the pipeline from a file (so errors name it) and runs it; its audio inputs
    listen."""
    path = tmp_path / "voice.yaml"
    path.write_text(yaml.safe_dump(pipeline))
    config = load_pipeline(path)
    outlets = Outlets(config)
    running = Pipeline(config, outlets, speaking=outlets.speaking)
    sources = [AudioSource(name, route.input, partial(running.submit, name), lambda r: None,
                           speaking=running.speaking)
               for name, route in config.routes.items() if route.input.audio is not None]
    running.start()
    for source in sources:
        source.start()
    try:
        yield LocalGateway(config, running, outlets, sources)
    finally:
        for source in sources:
            source.stop()
        running.stop()
        outlets.close()
