"""The speech service's OpenAI-compatible API through the official `openai` client, against a
real `oricf serve asr --http-listen` process: real speech from espeak-ng in WAV, FLAC,
OGG/Opus and MP3 (made by FFmpeg), in every response format, and the refusals."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import openai
import pytest

from oricf.audio import encode_wav
from tests.support.openai_http import HttpService, client
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words

MODEL = "whisper-tiny-en"
RATE = 16000
MAX_UPLOAD_MB = 1  # the session's asr_small_uploads


@pytest.fixture
def api(asr_small_uploads: HttpService) -> openai.OpenAI:
    return client(asr_small_uploads)


@pytest.fixture(scope="module")
def question_wav() -> bytes:
    return encode_wav(speech(QUESTION), RATE)


def encoded(wav: bytes, suffix: str, folder: Path) -> bytes:
    source, target = folder / "q.wav", folder / f"q.{suffix}"
    source.write_bytes(wav)
    codec = ["-c:a", "libopus"] if suffix == "ogg" else []
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-i", str(source), *codec,
                    str(target)], check=True, timeout=60)
    return target.read_bytes()


@pytest.mark.parametrize("suffix", ["wav", "flac", "ogg", "mp3"])
def test_real_speech_in_each_format_is_transcribed(api: openai.OpenAI, question_wav: bytes,
                                                   suffix: str, tmp_path: Path) -> None:
    data = question_wav if suffix == "wav" else encoded(question_wav, suffix, tmp_path)
    result = api.audio.transcriptions.create(model=MODEL, file=(f"q.{suffix}", data))
    assert words(result.text) == list(QUESTION_WORDS)


def test_text_format_is_the_bare_transcript(api: openai.OpenAI, question_wav: bytes) -> None:
    text = api.audio.transcriptions.create(model=MODEL, file=("q.wav", question_wav),
                                           response_format="text", language="en")
    assert isinstance(text, str) and words(text) == list(QUESTION_WORDS)


def test_verbose_json_has_timed_segments(api: openai.OpenAI) -> None:
    # Two questions with a second of silence between them: two segments, in order.
    gap = np.zeros(RATE, dtype=np.int16)
    audio = np.concatenate([speech(QUESTION), gap, speech("Stop moving and turn left")])
    result = api.audio.transcriptions.create(
        model=MODEL, file=("two.wav", encode_wav(audio, RATE)), response_format="verbose_json",
        timestamp_granularities=["segment"])
    assert result.duration == pytest.approx(len(audio) / RATE)
    segments = result.segments or []
    assert len(segments) == 2
    assert words(segments[0].text) == list(QUESTION_WORDS)
    assert words(segments[1].text) == ["stop", "moving", "and", "turn", "left"]
    assert 0 <= segments[0].start < segments[0].end < segments[1].start < segments[1].end
    assert segments[1].end <= result.duration
    assert words(result.text) == words(segments[0].text) + words(segments[1].text)


@pytest.mark.parametrize(("upload", "options", "error", "says"), [
    (("notes.wav", b"this is not audio at all"), {}, openai.BadRequestError,
     "not audio this service reads"),
    (("q.ogg", b"OggS" + bytes(2000)), {}, openai.BadRequestError, "cannot decode the OGG"),
    (None, {"response_format": "srt"}, openai.BadRequestError, "'srt' is not one of"),
    (None, {"language": "de"}, openai.BadRequestError, "language 'de' is not supported"),
    (None, {"prompt": "robot words"}, openai.BadRequestError, "prompt: not supported"),
    (None, {"model": "whisper-1"}, openai.NotFoundError, "serves 'whisper-tiny-en'"),
])
def test_bad_uploads_are_refused_with_the_reason(
        api: openai.OpenAI, question_wav: bytes, upload: tuple[str, bytes] | None,
        options: dict[str, object], error: type[openai.APIStatusError], says: str) -> None:
    options = {"model": MODEL, "file": upload or ("q.wav", question_wav), **options}
    with pytest.raises(error) as refused:
        api.audio.transcriptions.create(**options)  # type: ignore[call-overload]
    assert says in refused.value.message


def test_an_upload_over_the_limit_is_413(api: openai.OpenAI) -> None:
    too_long = encode_wav(np.zeros(RATE * 40, dtype=np.int16), RATE)  # 1.2 MB
    assert len(too_long) > MAX_UPLOAD_MB * 1024 * 1024
    with pytest.raises(openai.APIStatusError) as refused:
        api.audio.transcriptions.create(model=MODEL, file=("long.wav", too_long))
    assert refused.value.status_code == 413


def test_audio_over_the_duration_limit_is_refused(api: openai.OpenAI, tmp_path: Path) -> None:
    # 40 s of silence is a small FLAC file but over audio.max_audio_s once decoded.
    flac = encoded(encode_wav(np.zeros(RATE * 40, dtype=np.int16), RATE), "flac", tmp_path)
    assert len(flac) < MAX_UPLOAD_MB * 1024 * 1024
    with pytest.raises(openai.BadRequestError) as refused:
        api.audio.transcriptions.create(model=MODEL, file=("long.flac", flac))
    assert "over the limit of 30 s" in refused.value.message


def test_models_lists_the_served_model(api: openai.OpenAI) -> None:
    assert [model.id for model in api.models.list()] == [MODEL]
