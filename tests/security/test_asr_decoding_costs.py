"""What decoding the audio of one request may cost the speech recognition service: small files
that expand into many samples (30 s of silence at 384 kHz in 8 channels is a FLAC file of
100 KB), FLAC headers that lie about the length, WAV files of many channels and WAV headers that
lie about their data, sent over HTTP and gRPC to real `oricf serve asr --http-listen`
processes of their own. Each is refused with a 400 / INVALID_ARGUMENT naming its limit, or
decoded in bounded pieces; the process's peak resident memory (VmHWM) grows by a bounded
amount, and real speech is still transcribed right."""

from __future__ import annotations

import struct
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import grpc
import httpx
import numpy as np
import pytest

from oricf.audio import encode_wav, wav_header
from oricf.v1 import speech_pb2, speech_pb2_grpc
from tests.support.openai_http import HttpService, http_service, overlay
from tests.support.peak_memory import memory_kb
from tests.support.services import CHANNEL_OPTIONS
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words

T = TypeVar("T")

RATE = 384_000
CHANNELS = 8
SECONDS = 29.5  # inside audio.max_audio_s (30)
# Beyond what the same request's recognition and the upload itself take: the model's input
# (2 MB) and one block of the file's samples at a time (8 MB at most). Decoding the 384 kHz
# file at once took about 950 MB more, a 24 MB WAV file of 32 channels about 70 MB more.
MAX_GROWTH_MB = 40
RAISED_DECODED_MB = 256  # lets the 384 kHz file (181 MB of samples) be decoded whole


def peak_growth_mb(service: HttpService, send: Callable[[], T]) -> tuple[T, float]:
    """send()'s result, and how far above its resident memory before the call the service's
    peak went meanwhile (writing 5 to clear_refs resets a process's peak to its current
    resident memory)."""
    pid = service.process.pid
    Path(f"/proc/{pid}/clear_refs").write_text("5")
    before = memory_kb(pid, "VmRSS")
    result = send()
    return result, (memory_kb(pid, "VmHWM") - before) / 1024


@pytest.fixture(scope="module")
def silent_flac(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """29.5 s of silence at 384 kHz in 8 channels: about 100 KB, 173 MB of samples."""
    path = tmp_path_factory.mktemp("flac") / "silence.flac"
    subprocess.run(["sox", "--no-dither", "-n", "-r", str(RATE), "-c", str(CHANNELS), "-b", "16",
                    str(path), "trim", "0", str(SECONDS)], check=True, timeout=120)
    data = path.read_bytes()
    assert len(data) < 200_000
    return data


def lying_flac(flac: bytes, total_samples: int) -> bytes:
    """The file with its STREAMINFO claiming `total_samples` frames (0: unknown)."""
    assert flac[:4] == b"fLaC" and flac[4] & 0x7F == 0  # STREAMINFO comes first
    offset = 8 + 10  # past the block header and the block and frame sizes
    (packed,) = struct.unpack_from(">Q", flac, offset)
    packed = (packed & ~((1 << 36) - 1)) | total_samples
    return flac[:offset] + struct.pack(">Q", packed) + flac[offset + 8:]


def many_channel_wav(megabytes: float, channels: int = 32, rate: int = RATE) -> bytes:
    frames = int(megabytes * 1024 * 1024) // (2 * channels)
    return encode_wav(np.zeros((frames, channels), dtype=np.int16), rate)


def transcribe(service: HttpService, name: str, data: bytes) -> httpx.Response:
    return httpx.post(f"{service.base_url}/v1/audio/transcriptions", timeout=120,
                      files={"file": (name, data)})


def refused(service: HttpService, name: str, data: bytes) -> str:
    """The refusal's message; the call's memory beyond the upload is bounded."""
    response, growth = peak_growth_mb(service, lambda: transcribe(service, name, data))
    assert response.status_code == 400, (response.status_code, response.text)
    assert growth < MAX_GROWTH_MB + len(data) / 2**20, f"peak grew by {growth:.0f} MiB"
    return str(response.json()["error"]["message"])


def transcribe_silence_within_bounds(service: HttpService, name: str, data: bytes,
                                     seconds: float) -> None:
    """A file of silence is transcribed as the same length of silence at 16 kHz mono is, and
    the call's memory is bounded by what recognising that takes, plus the upload and
    MAX_GROWTH_MB."""
    reference = encode_wav(np.zeros(int(seconds * 16000), dtype=np.int16), 16000)
    expected, recognising = peak_growth_mb(
        service, lambda: transcribe(service, "reference.wav", reference))
    assert expected.status_code == 200, expected.text
    response, growth = peak_growth_mb(service, lambda: transcribe(service, name, data))
    assert response.status_code == 200, response.text
    limit = recognising + MAX_GROWTH_MB + len(data) / 2**20
    assert growth < limit, f"peak grew by {growth:.0f} MiB, recognition alone {recognising:.0f}"
    assert response.json()["text"] == expected.json()["text"]


def hears_the_question(service: HttpService) -> None:
    response = transcribe(service, "q.wav", encode_wav(speech(QUESTION), 16000))
    assert response.status_code == 200, response.text
    assert words(response.json()["text"]) == list(QUESTION_WORDS)


@pytest.fixture(scope="module")
def asr_large_messages(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    """The service with its shipped limits, a larger gRPC message for the many-channel case."""
    folder = tmp_path_factory.mktemp("asr")
    settings = overlay(folder, {"server": {"max_message_mb": 40}})
    with http_service("asr", "--overlay", settings) as service:
        hears_the_question(service)  # the model's first run allocates for good
        yield service


@pytest.fixture(scope="module")
def asr_raised(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    """The service with audio.max_decoded_mb raised: the 384 kHz file is decoded whole."""
    folder = tmp_path_factory.mktemp("asr-raised")
    settings = overlay(folder, {"audio": {"max_decoded_mb": RAISED_DECODED_MB}})
    with http_service("asr", "--overlay", settings) as service:
        hears_the_question(service)
        yield service


def test_a_flac_file_whose_header_declares_too_many_samples_is_refused_before_decoding(
        asr_large_messages: HttpService, silent_flac: bytes) -> None:
    for _ in range(4):
        says = refused(asr_large_messages, "silence.flac", silent_flac)
        assert says.startswith("the FLAC file's header: 29.5 s at 384000 Hz in 8 channel(s)")
        assert says.endswith("over the limit of 32 MB (audio.max_decoded_mb)")
    hears_the_question(asr_large_messages)


@pytest.mark.parametrize("declared", [0, RATE])  # unknown; one second
def test_a_flac_file_whose_header_lies_is_refused_while_it_is_decoded(
        asr_large_messages: HttpService, silent_flac: bytes, declared: int) -> None:
    says = refused(asr_large_messages, "lies.flac", lying_flac(silent_flac, declared))
    assert says.startswith("audio decoded so far:")
    assert says.endswith("over the limit of 32 MB (audio.max_decoded_mb)")


def test_a_flac_file_within_raised_limits_is_decoded_in_bounded_pieces(
        asr_raised: HttpService, silent_flac: bytes) -> None:
    transcribe_silence_within_bounds(asr_raised, "silence.flac", silent_flac, SECONDS)
    hears_the_question(asr_raised)


def test_a_wav_file_of_many_channels_is_mixed_down_in_bounded_pieces(
        asr_large_messages: HttpService) -> None:
    wav = many_channel_wav(24)  # 1 s at 384 kHz in 32 channels, under the upload limit
    transcribe_silence_within_bounds(asr_large_messages, "many.wav", wav,
                                     len(wav) / (2 * 32 * RATE))


@pytest.mark.parametrize(("header", "says"), [
    # "the data runs to the end of the file", 24 MB of it at 8 kHz mono: 26 minutes
    (wav_header(8000, 1, 0x7FFFFFFF), "over the limit of 30 s (audio.max_audio_s)"),
    # 256 MB of data declared, 24 MB present
    (wav_header(RATE, 8, 0x0FFFFFFF), "truncated WAV file"),
])
def test_wav_headers_that_lie_about_their_data_are_refused(
        asr_large_messages: HttpService, header: bytes, says: str) -> None:
    assert says in refused(asr_large_messages, "lies.wav", header + bytes(24 * 1024 * 1024))


def test_grpc_transcribe_bounds_the_decoded_size(asr_large_messages: HttpService) -> None:
    """What gRPC itself holds of a message (docs/services.md) varies too much from call to
    call to measure the conversion beside it: tests/audio measures that on its own."""
    data = bytes(36 * 1024 * 1024)  # 1.5 s at 384 kHz in 32 channels: 36 MB of samples
    audio = speech_pb2.Audio(data=data, encoding="pcm_s16le", sample_rate=RATE, channels=32)
    many = speech_pb2.Audio(data=many_channel_wav(30), encoding="wav")  # 30 MB: decoded
    with grpc.insecure_channel(asr_large_messages.grpc_address, options=CHANNEL_OPTIONS) as channel:
        stub = speech_pb2_grpc.SpeechRecognizerStub(channel)
        with pytest.raises(grpc.RpcError) as refusal:
            stub.Transcribe(speech_pb2.TranscribeRequest(audio=audio), timeout=60)
        reply = stub.Transcribe(speech_pb2.TranscribeRequest(audio=many), timeout=60)
    assert refusal.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert (refusal.value.details() or "").startswith(
        "audio: 1.5 s at 384000 Hz in 32 channel(s), 36.0 MB of 16-bit samples, over the "
        "limit of 32 MB (audio.max_decoded_mb)")
    assert reply.text == ""
    hears_the_question(asr_large_messages)
