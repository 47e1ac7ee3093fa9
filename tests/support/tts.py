"""The speech-synthesis service for tests: a pytest fixture and helpers.

    from tests.support.tts import tts_service  # the fixture, in a test module

`tts_service` is a real `tts` service (both shipped voices loaded: Piper `joe`, the default,
and `espeak`) started in-process on 127.0.0.1:0 once per test module; `.address` is its
gRPC address and `.channel` an open channel to it.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from oricf.v1 import synthesis_pb2, synthesis_pb2_grpc
from tests.support.services import RunningService, running_service

VOICES = ("joe", "espeak")  # the shipped voices: Piper (neural) and espeak-ng


@pytest.fixture(scope="module")
def tts_service() -> Iterator[RunningService]:
    with running_service("tts") as service:
        yield service


def stub(service: RunningService) -> synthesis_pb2_grpc.SpeechSynthesizerStub:
    return synthesis_pb2_grpc.SpeechSynthesizerStub(service.channel)


def samples(reply: synthesis_pb2.SynthesizedAudio) -> np.ndarray:
    """The int16 samples of a pcm_s16le reply."""
    assert reply.audio.encoding == "pcm_s16le"
    return np.frombuffer(reply.audio.data, dtype="<i2")
