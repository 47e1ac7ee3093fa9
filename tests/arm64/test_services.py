"""The model services as an Arm robot runs them: each started in the emulated arm64 root
with its shipped settings, and asked from this machine over 127.0.0.1 what the x86-64 tests
ask. The answers are checked the way tests/services checks them here."""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from typing import TypeVar

import pytest

from oricf.v1 import (
    common_pb2,
    detector_pb2,
    detector_pb2_grpc,
    language_pb2,
    language_pb2_grpc,
    speech_pb2,
    speech_pb2_grpc,
    synthesis_pb2,
    synthesis_pb2_grpc,
)
from tests.arm64.conftest import ServiceInRoot
from tests.arm64.root import run_in_root
from tests.support.data import image, video_frames
from tests.support.detections import count
from tests.support.services import RunningService
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words

pytestmark = pytest.mark.arm64
ANSWER_TIMEOUT_S = 600   # one answer of a model under emulation (seconds; a deadline, not a bound)
# What runs in the root: its machine, and that the native libraries it loads are Arm code
# (ELF e_machine 183, EM_AARCH64): onnxruntime's, CTranslate2's and the llama.cpp wheel's.
ARCHITECTURES = """
import ctypes.util, importlib, pathlib, platform
print(platform.machine())
for name in ("onnxruntime", "ctranslate2", "llama_cpp"):
    folder = pathlib.Path(importlib.import_module(name).__file__).parent
    for library in sorted(folder.rglob("*.so*")):
        print(name, library.name, int.from_bytes(library.read_bytes()[18:20], "little"))
"""


T = TypeVar("T")


def timed(what: str, call: Callable[[], T]) -> T:
    """call()'s result; how long it took under emulation goes to the test's output."""
    started = time.monotonic()
    result = call()
    print(f"arm64 {what}: {time.monotonic() - started:.1f} s")
    return result


def test_the_root_runs_arm_code(arm64_root: str) -> None:
    lines = run_in_root("/opt/oricf/venv/bin/python", "-c", ARCHITECTURES).splitlines()
    assert lines[0] == "aarch64"
    libraries = [line.split() for line in lines[1:]]
    assert {name for name, _, _ in libraries} == {"onnxruntime", "ctranslate2", "llama_cpp"}
    assert all(machine == "183" for _, _, machine in libraries), libraries


def test_the_detector_counts_people_on_the_video(arm64_detector: ServiceInRoot) -> None:
    stub = detector_pb2_grpc.DetectorStub(arm64_detector.channel)
    jpeg = common_pb2.Image(data=image("person.jpg").read_bytes(), encoding="jpeg")
    photo = timed("detector, person.jpg", lambda: stub.Detect(
        detector_pb2.DetectRequest(image=jpeg, labels=["person"]), timeout=ANSWER_TIMEOUT_S))
    assert count(photo, "person") == 1
    counts = []
    for frame in video_frames([0, 150, 300, 450, 600]):
        height, width = frame.shape[:2]
        raw = common_pb2.Image(data=frame.tobytes(), encoding="bgr8", width=width, height=height)
        reply = stub.Detect(detector_pb2.DetectRequest(image=raw, labels=["person"]),
                            timeout=ANSWER_TIMEOUT_S)
        counts.append(count(reply, "person"))
    # vtest.avi shows a street with a handful of pedestrians in every frame.
    assert all(2 <= c <= 12 for c in counts), counts


def test_speech_recognition_transcribes_a_spoken_question(arm64_asr: ServiceInRoot) -> None:
    samples = speech(QUESTION)
    audio = speech_pb2.Audio(data=samples.astype("<i2").tobytes(), encoding="pcm_s16le",
                             sample_rate=16000, channels=1)
    reply = timed("asr, the question", lambda: speech_pb2_grpc.SpeechRecognizerStub(
        arm64_asr.channel).Transcribe(speech_pb2.TranscribeRequest(audio=audio, language="en"),
                              timeout=ANSWER_TIMEOUT_S))
    assert tuple(words(reply.text)) == QUESTION_WORDS


def test_the_language_model_answers_with_the_count(arm64_llm: ServiceInRoot) -> None:
    request = language_pb2.GenerateRequest(
        prompt="How many people do you see?",
        facts=[common_pb2.Fact(name="people_count", integer=3)])
    reply = timed("llm, the answer", lambda: language_pb2_grpc.LanguageModelStub(
        arm64_llm.channel).Generate(request, timeout=ANSWER_TIMEOUT_S))
    assert re.search(r"\b(3|three)\b", reply.text.lower()), reply.text


def test_speech_synthesis_speaks_words_heard_back_here(arm64_tts: ServiceInRoot,
                                                       asr: RunningService) -> None:
    request = synthesis_pb2.SynthesizeRequest(text="I can see three people.")
    reply = timed("tts, one sentence", lambda: synthesis_pb2_grpc.SpeechSynthesizerStub(
        arm64_tts.channel).Synthesize(request, timeout=ANSWER_TIMEOUT_S))
    assert reply.audio.encoding == "pcm_s16le" and reply.audio.channels == 1
    # This machine's own speech recognition (x86-64) is the listener.
    heard = speech_pb2_grpc.SpeechRecognizerStub(asr.channel).Transcribe(
        speech_pb2.TranscribeRequest(audio=speech_pb2.Audio(
            data=reply.audio.data, encoding="pcm_s16le", sample_rate=reply.audio.sample_rate,
            channels=1), language="en"), timeout=60)
    assert words(heard.text) == ["i", "can", "see", "three", "people"], heard.text
