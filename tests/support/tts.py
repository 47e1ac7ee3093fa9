"""Helpers for tests of the speech-synthesis service. The service itself is the session
fixture `tts` (tests/conftest.py): both shipped voices loaded, Piper `joe` (the default) and
`espeak`; `.address` is its gRPC address and `.channel` an open channel to it."""

from __future__ import annotations

import numpy as np

from oricf.v1 import synthesis_pb2, synthesis_pb2_grpc
from tests.support.services import RunningService

VOICES = ("joe", "espeak")  # the shipped voices: Piper (neural) and espeak-ng


def stub(service: RunningService) -> synthesis_pb2_grpc.SpeechSynthesizerStub:
    return synthesis_pb2_grpc.SpeechSynthesizerStub(service.channel)


def samples(reply: synthesis_pb2.SynthesizedAudio) -> np.ndarray:
    """The int16 samples of a pcm_s16le reply."""
    assert reply.audio.encoding == "pcm_s16le"
    return np.frombuffer(reply.audio.data, dtype="<i2")
