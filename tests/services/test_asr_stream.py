"""TranscribeStream: microphone-sized chunks in, one transcript per utterance out."""

import logging
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

import grpc
import numpy as np
import pytest

from oricf.v1 import speech_pb2, speech_pb2_grpc
from tests.support.services import RunningService, running_service
from tests.support.speech import QUESTION, speech, words

COMMAND = "Stop moving and turn left"
CHUNK_MS = 20   # a typical microphone buffer


def silence(seconds: float, rate: int = 16000) -> np.ndarray:
    return np.zeros(int(seconds * rate), dtype=np.int16)


def chunks(samples: np.ndarray, rate: int = 16000, channels: int = 1,
           chunk_ms: int = CHUNK_MS) -> Iterator[speech_pb2.TranscribeStreamRequest]:
    """The format in the first message only, then bare chunks, as a microphone client sends."""
    data = samples.astype("<i2").tobytes()
    size = rate * chunk_ms // 1000 * 2 * channels
    for offset in range(0, len(data), size):
        audio = speech_pb2.Audio(data=data[offset:offset + size])
        if offset == 0:
            audio.encoding, audio.sample_rate, audio.channels = "pcm_s16le", rate, channels
        yield speech_pb2.TranscribeStreamRequest(audio=audio)


@pytest.fixture
def stub(asr: RunningService) -> speech_pb2_grpc.SpeechRecognizerStub:
    return speech_pb2_grpc.SpeechRecognizerStub(asr.channel)


def transcripts(stub: speech_pb2_grpc.SpeechRecognizerStub,
                requests: Iterable[speech_pb2.TranscribeStreamRequest]
                ) -> list[speech_pb2.Transcript]:
    return list(stub.TranscribeStream(iter(requests), timeout=60))


def test_one_transcript_per_utterance(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    first, second = speech(QUESTION), speech(COMMAND, voice="en-gb")
    audio = np.concatenate([silence(0.5), first, silence(1.0), second, silence(1.0)])
    results = transcripts(stub, chunks(audio))
    assert len(results) == 2, [r.text for r in results]
    assert {"many", "people", "see"} <= set(words(results[0].text)), results[0].text
    assert words(results[1].text) == ["stop", "moving", "and", "turn", "left"], results[1].text
    assert [r.utterance for r in results] == [0, 1]
    # Each utterance lies where its speech was put in the stream (with the pad around it).
    first_end = (8000 + len(first)) / 16000
    assert 0.4 <= results[0].start_s < results[0].end_s <= first_end + 0.1
    assert first_end + 0.5 < results[1].start_s < results[1].end_s <= len(audio) / 16000
    for result in results:
        assert result.duration_s == pytest.approx(result.end_s - result.start_s, abs=0.001)
        assert result.timings.inference_ms > 0 and result.timings.preprocess_ms > 0
        assert result.timings.total_ms >= result.timings.inference_ms


def test_a_stream_ending_mid_utterance_is_flushed(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    audio = np.concatenate([silence(0.3), speech(QUESTION)[:-3200]])  # cut right after speech
    results = transcripts(stub, chunks(audio))
    assert len(results) == 1
    assert {"many", "people"} <= set(words(results[0].text)), results[0].text


def test_silence_alone_gives_nothing(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    assert transcripts(stub, chunks(silence(2.0))) == []


def test_an_empty_stream_gives_nothing(stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    assert transcripts(stub, []) == []


def test_48k_stereo_in_chunks_that_split_frames(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    mono = np.concatenate([speech(COMMAND, rate=48000), silence(0.8, 48000)])
    data = np.stack([mono, mono], axis=1).astype("<i2").tobytes()
    sizes = [1001, 7, 3, 4097]  # never a whole frame (4 bytes)
    requests, offset, turn = [], 0, 0
    while offset < len(data):
        size = sizes[turn % len(sizes)]
        audio = speech_pb2.Audio(data=data[offset:offset + size], encoding="pcm_s16le",
                                 sample_rate=48000, channels=2)
        requests.append(speech_pb2.TranscribeStreamRequest(audio=audio))
        offset, turn = offset + size, turn + 1
    results = transcripts(stub, requests)
    assert [words(r.text) for r in results] == [["stop", "moving", "and", "turn", "left"]]


BAD_STREAMS = {
    "wav in a stream": ([speech_pb2.Audio(data=bytes(64), encoding="wav")],
                        "must set audio.encoding to 'pcm_s16le'"),
    "no format": ([speech_pb2.Audio(data=bytes(64))], "must set audio.encoding"),
    "zero sample rate": ([speech_pb2.Audio(data=bytes(64), encoding="pcm_s16le")],
                         "sample_rate must be > 0"),
    "rate changes": ([speech_pb2.Audio(data=bytes(64), encoding="pcm_s16le", sample_rate=16000),
                      speech_pb2.Audio(data=bytes(64), sample_rate=8000)],
                     "sample_rate changed mid-stream from 16000 to 8000 Hz"),
    "encoding changes": ([speech_pb2.Audio(data=bytes(64), encoding="pcm_s16le",
                                           sample_rate=16000),
                          speech_pb2.Audio(data=bytes(64), encoding="wav")],
                         "encoding changed mid-stream"),
    "channels change": ([speech_pb2.Audio(data=bytes(64), encoding="pcm_s16le",
                                          sample_rate=16000, channels=1),
                         speech_pb2.Audio(data=bytes(64), channels=2)],
                        "channels changed mid-stream from 1 to 2"),
    "stray byte at the end": ([speech_pb2.Audio(data=bytes(65), encoding="pcm_s16le",
                                                sample_rate=16000)],
                              "1 stray byte(s)"),
}


@pytest.mark.parametrize("case", BAD_STREAMS)
def test_bad_stream_is_invalid_argument_and_the_service_goes_on(
        stub: speech_pb2_grpc.SpeechRecognizerStub, case: str) -> None:
    audios, message = BAD_STREAMS[case]
    requests = [speech_pb2.TranscribeStreamRequest(audio=a) for a in audios]
    with pytest.raises(grpc.RpcError) as error:
        transcripts(stub, requests)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert message in error.value.details()
    good = transcripts(stub, chunks(np.concatenate([speech(QUESTION), silence(0.6)])))
    assert len(good) == 1 and "people" in words(good[0].text)


def test_long_speech_is_cut_at_max_utterance() -> None:
    overrides = {"endpointing": {"max_utterance_s": 2.0}}
    talk = np.concatenate([speech(QUESTION)[3200:-3200]] * 3)  # about 5 s without a pause
    with running_service("asr", overrides) as service:
        stub = speech_pb2_grpc.SpeechRecognizerStub(service.channel)
        results = transcripts(stub, chunks(np.concatenate([talk, silence(1.0)])))
    assert len(results) >= 3, [r.text for r in results]
    assert all(r.duration_s <= 2.0 + 1e-6 for r in results)
    assert sum("people" in words(r.text) for r in results) >= 2


def test_concurrent_streams_keep_their_own_state(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    texts = {QUESTION: speech(QUESTION), COMMAND: speech(COMMAND, voice="en-gb")}
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {text: pool.submit(transcripts, stub, chunks(np.concatenate([a, silence(0.8)])))
                   for text, a in texts.items()}
        results = {text: future.result(timeout=120) for text, future in futures.items()}
    assert [len(r) for r in results.values()] == [1, 1]
    assert {"many", "people", "see"} <= set(words(results[QUESTION][0].text))
    assert words(results[COMMAND][0].text) == ["stop", "moving", "and", "turn", "left"]


def test_a_deadline_ends_a_stream_and_the_service_goes_on(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    audio = list(chunks(silence(5.0)))
    sent: list[speech_pb2.TranscribeStreamRequest] = []

    def slow_microphone() -> Iterator[speech_pb2.TranscribeStreamRequest]:
        for request in audio:
            time.sleep(CHUNK_MS / 1000)   # real time: 5 s of audio takes 5 s
            sent.append(request)
            yield request

    with pytest.raises(grpc.RpcError) as error:
        list(stub.TranscribeStream(slow_microphone(), timeout=0.5))
    assert error.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    assert len(sent) < len(audio)  # ended at the deadline, not at the end of the audio
    good = transcripts(stub, chunks(np.concatenate([speech(QUESTION), silence(0.6)])))
    assert len(good) == 1 and "people" in words(good[0].text)


def _one_chunk(samples: np.ndarray, rate: int) -> speech_pb2.TranscribeStreamRequest:
    return speech_pb2.TranscribeStreamRequest(audio=speech_pb2.Audio(
        data=samples.astype("<i2").tobytes(), encoding="pcm_s16le", sample_rate=rate,
        channels=1))


def test_a_tiny_sample_rate_is_refused_before_any_work(
        stub: speech_pb2_grpc.SpeechRecognizerStub) -> None:
    """8 KB of PCM at 1 Hz would be over an hour of audio to resample and scan."""
    request = _one_chunk(np.zeros(4096, np.int16), rate=1)
    with pytest.raises(grpc.RpcError) as error:
        transcripts(stub, [request])
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "below the 8000 Hz minimum" in (error.value.details() or "")


def test_a_stream_longer_than_its_limit_is_refused() -> None:
    with running_service("asr", {"audio": {"max_stream_s": 2}}) as asr:
        stub = speech_pb2_grpc.SpeechRecognizerStub(asr.channel)
        with pytest.raises(grpc.RpcError) as error:
            transcripts(stub, chunks(silence(3.0)))
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "more than 2 s of audio (audio.max_stream_s)" in (error.value.details() or "")


def test_the_deadline_is_checked_during_voice_activity_detection(
        stub: speech_pb2_grpc.SpeechRecognizerStub, caplog: pytest.LogCaptureFixture) -> None:
    """Ten minutes of noise in one message with a short deadline: the scan stops at the
    deadline instead of running on after the caller has gone, and the service goes on."""
    caplog.set_level(logging.DEBUG, logger="oricf.services.runtime.errors")
    noise = np.random.default_rng(0).integers(-2000, 2000, 8000 * 590, dtype=np.int16)
    with pytest.raises(grpc.RpcError) as error:
        list(stub.TranscribeStream(iter([_one_chunk(noise, 8000)]), timeout=1.0))
    assert error.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    stopped = time.monotonic() + 60  # a bound against a hang, not a timing figure
    # Stopped by the deadline check, or, when gRPC has already ended the call at its
    # deadline, by the check that the caller is still there: either way the scan stopped.
    while not any(stop in r.getMessage() for r in caplog.records
                  for stop in ("during voice activity detection", "the caller went away")):
        assert time.monotonic() < stopped, "the scan did not stop at the caller's deadline"
        time.sleep(0.05)
    answer = transcripts(stub, chunks(np.concatenate([silence(0.5), speech(QUESTION),
                                                      silence(1.0)])))
    assert words(answer[0].text) == words(QUESTION)
