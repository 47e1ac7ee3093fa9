"""grpcurl calls the speech service with no .proto files, through server reflection."""

import base64
import json

from oricf.audio import encode_wav
from tests.support.grpcurl import grpcurl
from tests.support.services import RunningService
from tests.support.speech import QUESTION, QUESTION_WORDS, speech, words


def test_list_shows_the_service(asr: RunningService) -> None:
    services = grpcurl(asr.address, "list").split()
    assert {"oricf.v1.SpeechRecognizer", "grpc.health.v1.Health"} <= set(services)
    methods = grpcurl(asr.address, "list", "oricf.v1.SpeechRecognizer").split()
    assert methods == ["oricf.v1.SpeechRecognizer.GetModelInfo",
                       "oricf.v1.SpeechRecognizer.Transcribe",
                       "oricf.v1.SpeechRecognizer.TranscribeStream"]


def test_transcribe_pcm_with_a_json_body(asr: RunningService) -> None:
    pcm = speech(QUESTION).astype("<i2").tobytes()
    body = json.dumps({"audio": {"data": base64.b64encode(pcm).decode(),
                                 "encoding": "pcm_s16le", "sampleRate": 16000}})
    answer = json.loads(grpcurl(asr.address, "oricf.v1.SpeechRecognizer/Transcribe", data=body))
    assert set(QUESTION_WORDS) <= set(words(answer["text"])), answer
    assert answer["language"] == "en"
    assert answer["timings"]["inference_ms"] > 0  # grpcurl keeps proto field names


def test_transcribe_wav_with_an_inline_body(asr: RunningService) -> None:
    wav = base64.b64encode(encode_wav(speech(QUESTION, voice="en-gb"), 16000)).decode()
    body = json.dumps({"audio": {"data": wav, "encoding": "wav"}})
    answer = json.loads(grpcurl("-d", body, asr.address, "oricf.v1.SpeechRecognizer/Transcribe"))
    assert {"many", "people", "see"} <= set(words(answer["text"])), answer


def test_health_check(asr: RunningService) -> None:
    answer = json.loads(grpcurl("-d", '{"service": "oricf.v1.SpeechRecognizer"}', asr.address,
                                "grpc.health.v1.Health/Check"))
    assert answer["status"] == "SERVING"
