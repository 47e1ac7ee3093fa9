"""The speech service: real Whisper tiny.en on real synthesized speech, over a real channel."""

from collections.abc import Iterator

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.audio import encode_wav
from oricf.v1 import common_pb2, speech_pb2, speech_pb2_grpc
from tests.support.services import RunningService, running_service
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words


def pcm_request(samples: np.ndarray, rate: int = 16000, channels: int = 0,
                language: str = "") -> speech_pb2.TranscribeRequest:
    audio = speech_pb2.Audio(data=samples.astype("<i2").tobytes(), encoding="pcm_s16le",
                             sample_rate=rate, channels=channels)
    return speech_pb2.TranscribeRequest(audio=audio, language=language)


@pytest.fixture(scope="module")
def asr_25s() -> Iterator[RunningService]:
    with running_service("asr", {"audio": {"max_audio_s": 25}}) as service:
        yield service


@pytest.fixture
def stub(asr_25s: RunningService) -> speech_pb2_grpc.SpeechRecognizerStub:
    return speech_pb2_grpc.SpeechRecognizerStub(asr_25s.channel)


def test_transcribes_a_spoken_question(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    samples = speech(QUESTION)
    transcript = stub.Transcribe(pcm_request(samples), timeout=30)
    assert set(QUESTION_WORDS) <= set(words(transcript.text)), transcript.text
    assert transcript.language == "en"
    assert transcript.duration_s == pytest.approx(len(samples) / 16000, abs=0.01)
    timings = transcript.timings
    assert timings.decode_ms > 0 and timings.inference_ms > 0
    assert timings.total_ms >= timings.inference_ms + timings.decode_ms * 0.99


def test_wav_at_44k_stereo_is_resampled_and_mixed_down(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    mono = speech("Stop moving and turn left", rate=44100)
    # Speech on the left channel, a quieter copy on the right: the mix must still be speech.
    stereo = np.stack([mono, mono // 2], axis=1)
    audio = speech_pb2.Audio(data=encode_wav(stereo, 44100), encoding="wav")
    transcript = stub.Transcribe(speech_pb2.TranscribeRequest(audio=audio), timeout=30)
    assert words(transcript.text) == ["stop", "moving", "and", "turn", "left"], transcript.text
    assert transcript.duration_s == pytest.approx(len(mono) / 44100, abs=0.01)


@pytest.mark.parametrize(("rate", "channels"), [(8000, 1), (48000, 2), (22050, 0)])
def test_pcm_at_any_rate_and_channel_count(stub: speech_pb2_grpc.SpeechRecognizerStub,
                                           rate: int, channels: int) -> None:
    mono = speech(QUESTION, voice="en-gb", rate=rate)
    frames = np.repeat(mono[:, None], max(channels, 1), axis=1)
    transcript = stub.Transcribe(pcm_request(frames, rate, channels), timeout=30)
    assert {"many", "people", "see"} <= set(words(transcript.text)), transcript.text


def test_the_request_language_reaches_the_recognizer(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    samples = speech(QUESTION)
    default = stub.Transcribe(pcm_request(samples), timeout=30)
    english = stub.Transcribe(pcm_request(samples, language="en"), timeout=30)
    assert (english.text, english.language) == (default.text, "en")
    assert "people" in words(english.text)
    # tiny.en knows English only: another language is refused, never decoded as English.
    for language in ("de", "fr", "ja"):
        with pytest.raises(grpc.RpcError) as error:
            stub.Transcribe(pcm_request(samples, language=language), timeout=30)
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert f"language '{language}' is not supported by whisper-tiny-en (supported: en)" \
            in (error.value.details() or "")


def test_silence_gives_no_words(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    transcript = stub.Transcribe(pcm_request(np.zeros(16000, np.int16)), timeout=30)
    assert transcript.text == ""
    assert transcript.duration_s == pytest.approx(1.0)


def good_wav() -> bytes:
    return encode_wav(speech(QUESTION), 16000)


BAD_REQUESTS = {
    "no audio at all": (speech_pb2.Audio(), "audio encoding is missing"),
    "empty pcm": (speech_pb2.Audio(encoding="pcm_s16le", sample_rate=16000), "empty"),
    "empty wav": (speech_pb2.Audio(encoding="wav"), "empty"),
    "truncated wav": (speech_pb2.Audio(data=good_wav()[:20000], encoding="wav"), "truncated"),
    "not a wav": (speech_pb2.Audio(data=b"GIF89a" + bytes(500), encoding="wav"),
                  "not a WAV file"),
    "unknown encoding": (speech_pb2.Audio(data=bytes(100), encoding="opus"),
                         "unknown audio encoding 'opus'"),
    "zero sample rate": (speech_pb2.Audio(data=bytes(100), encoding="pcm_s16le"),
                         "sample_rate must be > 0"),
    "odd byte count": (speech_pb2.Audio(data=bytes(101), encoding="pcm_s16le",
                                        sample_rate=16000), "not a whole number of frames"),
    "too long": (speech_pb2.Audio(data=bytes(2 * 16000 * 26), encoding="pcm_s16le",
                                  sample_rate=16000), "over the limit of 25 s"),
}


@pytest.mark.parametrize("case", BAD_REQUESTS)
def test_bad_input_is_invalid_argument_and_the_service_goes_on(
        stub: speech_pb2_grpc.SpeechRecognizerStub, case: str) -> None:
    audio, message = BAD_REQUESTS[case]
    with pytest.raises(grpc.RpcError) as error:
        stub.Transcribe(speech_pb2.TranscribeRequest(audio=audio), timeout=30)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert message in error.value.details()
    good = speech_pb2.Audio(data=good_wav(), encoding="wav")
    transcript = stub.Transcribe(speech_pb2.TranscribeRequest(audio=good), timeout=30)
    assert "people" in words(transcript.text)


def test_health_is_serving(asr_25s: RunningService) -> None:
    health = health_pb2_grpc.HealthStub(asr_25s.channel)
    for service in ("", "oricf.v1.SpeechRecognizer"):
        status = health.Check(health_pb2.HealthCheckRequest(service=service), timeout=5).status
        assert status == health_pb2.HealthCheckResponse.SERVING


def test_model_info(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    info = stub.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=5)
    assert (info.service, info.model, info.license) == ("asr", "whisper-tiny-en", "MIT")
    assert info.sha256 == "1a5afae06a4db91c975c9a9d78be5cc110ee4ea022ad57d55492e4550e936b2a"
    assert info.runtime.startswith("ctranslate2 ") and "faster-whisper 1.2.1" in info.runtime
    assert list(info.providers) == ["cpu"]
    params = info.parameters
    assert (params["backend"], params["beam_size"], params["compute_type"]) == \
        ("faster-whisper", "5", "int8")
    assert params["threads"] == "2" and params["language"] == "en"
    assert params["vad"].startswith("silero_vad_v6.onnx (onnxruntime ")
    assert info.load_seconds > 0


def test_unavailable_until_the_model_is_loaded() -> None:
    with running_service("asr", load=False) as service:
        stub = speech_pb2_grpc.SpeechRecognizerStub(service.channel)
        with pytest.raises(grpc.RpcError) as error:
            stub.Transcribe(pcm_request(speech(QUESTION)), timeout=10)
        assert error.value.code() == grpc.StatusCode.UNAVAILABLE
        health = health_pb2_grpc.HealthStub(service.channel)
        status = health.Check(health_pb2.HealthCheckRequest(), timeout=5).status
        assert status == health_pb2.HealthCheckResponse.NOT_SERVING
