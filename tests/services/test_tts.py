"""The speech-synthesis service over real gRPC with both shipped voices (Piper on onnxruntime,
espeak-ng): audio of plausible length, sentence by sentence, understood by ORICF's own speech
recogniser, and every refusal a clear INVALID_ARGUMENT after which the service still serves."""

from __future__ import annotations

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.audio import parse_wav
from oricf.bench.asr import word_errors
from oricf.services.tts.text import normalise
from oricf.v1 import common_pb2, speech_pb2, speech_pb2_grpc, synthesis_pb2
from tests.support.services import RunningService
from tests.support.speech import words
from tests.support.tts import VOICES, samples, stub

# Answers a robot gives, with numbers in them: what must come out intelligible.
ANSWERS = [
    "I can see 3 people.",
    "There are 2 people near the door.",
    "The box is 12.5 m away.",
    "I counted 15 cups on the table.",
    "The battery is at 80%.",
    "Turn left in 5 seconds.",
    "My 1st task is to find 7 red boxes.",
    "It is 21 degrees in the kitchen.",
]
MAX_WER = 0.10
# Whisper spells some words either way; the reference is the voice's en-US spelling.
SPELLINGS = {"metres": "meters"}
RATE = 22050


def synthesize(service: RunningService, text: str, voice: str = "",
               **fields: object) -> synthesis_pb2.SynthesizedAudio:
    request = synthesis_pb2.SynthesizeRequest(text=text, voice=voice, **fields)  # type: ignore[arg-type]
    return stub(service).Synthesize(request, timeout=60)


def rms(pcm: np.ndarray) -> float:
    return float(np.sqrt(np.mean(pcm.astype(np.float64) ** 2)))


@pytest.mark.parametrize("voice", VOICES)
def test_each_voice_speaks_for_a_plausible_time(tts: RunningService,
                                                voice: str) -> None:
    reply = synthesize(tts, "I can see four people in the room.", voice)
    pcm = samples(reply)
    assert reply.voice == voice and reply.last
    assert reply.audio.sample_rate == RATE and reply.audio.channels == 1
    assert reply.duration_s == pytest.approx(len(pcm) / RATE)
    # Eight words at a speaking pace of 2-4 words a second.
    assert 1.2 < reply.duration_s < 5.0
    assert rms(pcm) > 300, "the audio is (nearly) silent"
    assert reply.text == "I can see four people in the room."
    assert reply.timings.inference_ms > 0 and reply.timings.total_ms >= reply.timings.inference_ms


def test_the_default_voice_is_the_piper_voice(tts: RunningService) -> None:
    assert synthesize(tts, "Hello.").voice == "joe"


@pytest.mark.parametrize("voice", VOICES)
def test_stream_sends_each_sentence_as_it_is_made(tts: RunningService,
                                                  voice: str) -> None:
    text = "Hello there. I can see 2 people! Shall I follow them?"
    chunks = list(stub(tts).SynthesizeStream(
        synthesis_pb2.SynthesizeRequest(text=text, voice=voice), timeout=60))
    assert [c.sentence for c in chunks] == [0, 1, 2]
    assert [c.last for c in chunks] == [False, False, True]
    assert [c.text for c in chunks] == ["Hello there.", "I can see two people!",
                                        "Shall I follow them?"]
    for chunk in chunks:
        assert chunk.duration_s == pytest.approx(len(samples(chunk)) / RATE)
        assert 0.3 < chunk.duration_s < 4.0
    # total_ms counts from the request: the first sentence is out before the last is made.
    assert chunks[0].timings.total_ms < chunks[-1].timings.total_ms


def test_stream_adds_up_to_the_whole_reply(tts: RunningService) -> None:
    """espeak-ng is deterministic: the streamed sentences, pauses included, are exactly the
    audio of one Synthesize."""
    text = "One sentence. And another one. The third."
    whole = samples(synthesize(tts, text, "espeak"))
    chunks = stub(tts).SynthesizeStream(
        synthesis_pb2.SynthesizeRequest(text=text, voice="espeak"), timeout=60)
    assert np.array_equal(np.concatenate([samples(c) for c in chunks]), whole)


@pytest.mark.parametrize("voice", VOICES)
def test_wav_encoding_is_a_wav_file(tts: RunningService, voice: str) -> None:
    reply = synthesize(tts, "A WAV file.", voice, encoding="wav")
    assert reply.audio.encoding == "wav"
    pcm = parse_wav(reply.audio.data)
    assert pcm.sample_rate == RATE and pcm.channels == 1
    assert len(pcm.samples) / RATE == pytest.approx(reply.duration_s)


@pytest.mark.parametrize("voice", VOICES)
def test_speed_changes_the_length(tts: RunningService, voice: str) -> None:
    text = "The quick brown fox jumps over the lazy dog."
    normal = synthesize(tts, text, voice).duration_s
    fast = synthesize(tts, text, voice, speed=2.0).duration_s
    slow = synthesize(tts, text, voice, speed=0.5).duration_s
    assert fast < 0.8 * normal < normal < 0.8 * slow


@pytest.mark.parametrize("voice", VOICES)
def test_answers_with_numbers_are_understood(tts: RunningService,
                                             asr: RunningService, voice: str) -> None:
    """Each answer spoken, then transcribed by the speech service (Whisper): word error
    rate at most 10% over the set, numbers compared as words on both sides."""
    recognizer = speech_pb2_grpc.SpeechRecognizerStub(asr.channel)
    errors = total = 0
    heard = []
    for answer in ANSWERS:
        reply = synthesize(tts, answer, voice)
        transcript = recognizer.Transcribe(speech_pb2.TranscribeRequest(
            audio=speech_pb2.Audio(data=reply.audio.data, encoding="pcm_s16le",
                                   sample_rate=reply.audio.sample_rate)), timeout=60).text
        reference = words(normalise(answer))
        hypothesis = [SPELLINGS.get(w, w) for w in words(normalise(transcript))]
        errors += word_errors(reference, hypothesis)
        total += len(reference)
        heard.append(transcript)
    assert errors / total <= MAX_WER, heard


BAD_REQUESTS = {
    "empty": {"text": ""},
    "white space": {"text": " \n\t "},
    "100 KB": {"text": "word " * 20_000},
    "unknown voice": {"text": "Hello.", "voice": "alloy"},
    "control character": {"text": "Hello\x1b[31m there."},
    "NUL": {"text": "Hel\x00lo."},
    "SSML": {"text": "<speak>Hello <break time='3s'/> there.</speak>"},
    "closing tag": {"text": "Hello </voice> there."},
    "phoneme brackets": {"text": "Say [[h@'loU]] there."},
    "punctuation only": {"text": "... !?"},
    "speed too high": {"text": "Hello.", "speed": 9.0},
    "speed negative": {"text": "Hello.", "speed": -1.0},
    "speed NaN": {"text": "Hello.", "speed": float("nan")},
    "encoding": {"text": "Hello.", "encoding": "mp3"},
}


@pytest.mark.parametrize("fields", BAD_REQUESTS.values(), ids=BAD_REQUESTS.keys())
def test_bad_input_is_invalid_argument_and_the_service_keeps_serving(
        tts: RunningService, fields: dict[str, object]) -> None:
    request = synthesis_pb2.SynthesizeRequest(**fields)  # type: ignore[arg-type]
    for call in (stub(tts).Synthesize,
                 lambda r, timeout: list(stub(tts).SynthesizeStream(r, timeout=timeout))):
        with pytest.raises(grpc.RpcError) as refused:
            call(request, timeout=30)
        assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert refused.value.details()
    health = health_pb2_grpc.HealthStub(tts.channel).Check(
        health_pb2.HealthCheckRequest(), timeout=10)
    assert health.status == health_pb2.HealthCheckResponse.SERVING
    assert synthesize(tts, "Still here.", "espeak").duration_s > 0.3


def test_refusals_say_what_is_wrong(tts: RunningService) -> None:
    cases = {"<speak>hi</speak>": "markup", "a\x07b": "U+0007", "x " * 2000: "2,000"}
    for text, said in cases.items():
        with pytest.raises(grpc.RpcError) as refused:
            synthesize(tts, text)
        assert said in refused.value.details()
    with pytest.raises(grpc.RpcError) as refused:
        synthesize(tts, "Hello.", "alloy")
    assert "joe" in refused.value.details() and "espeak" in refused.value.details()


def test_a_deadline_stops_a_long_text(tts: RunningService) -> None:
    long = " ".join(f"This is sentence number {i}." for i in range(60))
    with pytest.raises(grpc.RpcError) as refused:
        stub(tts).Synthesize(synthesis_pb2.SynthesizeRequest(text=long), timeout=0.5)
    assert refused.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    assert synthesize(tts, "Still here.").duration_s > 0.3


def test_model_info_names_the_voices_and_licence(tts: RunningService) -> None:
    info = stub(tts).GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=10)
    assert info.service == "tts" and info.model == "piper-joe-medium"
    assert info.sha256 == "58afce0321b8d9c46d7cdf9c16500cc55a793b4220212dba6b70fb788b3baf06"
    assert "CC0" in info.license and info.runtime.startswith("onnxruntime")
    assert info.parameters["voices"] == "joe,espeak"
    assert info.parameters["voice.joe.sample_rate"] == str(RATE)
    assert info.parameters["voice.espeak.engine"] == "espeak-ng"


def test_a_sentence_made_in_several_runs_is_understood(tts: RunningService,
                                                       asr: RunningService) -> None:
    """At speed 0.75 the Piper voice makes at most 150 phonemes at once (max_run_phonemes
    200 at speed 1): this sentence of 184 is made in two runs, cut at its comma."""
    sentence = ("I can see four people near the kitchen door and two dogs asleep on the sofa, "
                "and there is a small red box on the wooden table beside the open window at "
                "the end of the hall.")
    reply = synthesize(tts, sentence, "joe", speed=0.75)
    transcript = speech_pb2_grpc.SpeechRecognizerStub(asr.channel).Transcribe(
        speech_pb2.TranscribeRequest(audio=speech_pb2.Audio(
            data=reply.audio.data, encoding="pcm_s16le", sample_rate=reply.audio.sample_rate)),
        timeout=60).text
    reference = words(sentence)
    hypothesis = [SPELLINGS.get(w, w) for w in words(normalise(transcript))]
    assert word_errors(reference, hypothesis) / len(reference) <= MAX_WER, transcript
