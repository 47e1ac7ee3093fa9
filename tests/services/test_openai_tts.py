"""The speech service's OpenAI-compatible API through the official `openai` client, against a
real `oricf serve tts --http-listen` process: WAV and PCM from both voices, and the refusals
(OpenAI's 400 shape) after which the service still speaks."""

from __future__ import annotations

import httpx
import numpy as np
import openai
import pytest

from oricf.audio import parse_wav
from tests.support.openai_http import HttpService, client
from tests.support.tts import VOICES

MODEL = "oricf-tts"
RATE = 22050


@pytest.fixture
def api(tts_http: HttpService) -> openai.OpenAI:
    return client(tts_http)


@pytest.mark.parametrize("voice", VOICES)
def test_wav_from_each_voice(api: openai.OpenAI, voice: str) -> None:
    response = api.audio.speech.create(model=MODEL, voice=voice, response_format="wav",
                                       input="I can see 4 people. They are near the door.")
    pcm = parse_wav(response.content)
    assert pcm.sample_rate == RATE and pcm.channels == 1
    assert 1.5 < len(pcm.samples) / RATE < 6.0
    assert np.abs(pcm.samples.astype(np.int32)).max() > 1000
    assert response.response.headers["content-type"] == "audio/wav"


def test_pcm_is_raw_samples_at_the_stated_rate(api: openai.OpenAI) -> None:
    response = api.audio.speech.create(model=MODEL, voice="espeak", input="Hello there.",
                                       response_format="pcm", speed=1.0)
    assert response.response.headers["x-sample-rate"] == str(RATE)
    assert len(response.content) % 2 == 0
    assert 0.4 < len(response.content) / 2 / RATE < 3.0
    assert not response.content.startswith(b"RIFF")


def test_the_audio_streams_sentence_by_sentence(api: openai.OpenAI) -> None:
    text = " ".join(f"This is sentence {i}." for i in range(1, 7))
    with api.audio.speech.with_streaming_response.create(
            model=MODEL, voice="joe", input=text, response_format="pcm") as response:
        pieces = [len(piece) for piece in response.iter_bytes()]
    assert sum(pieces) / 2 / RATE > 6 * 0.8


def test_speed(api: openai.OpenAI) -> None:
    def seconds(speed: float) -> float:
        data = api.audio.speech.create(model=MODEL, voice="espeak", input="Faster and faster.",
                                       response_format="pcm", speed=speed).content
        return len(data) / 2 / RATE

    assert seconds(2.0) < 0.8 * seconds(1.0)


BAD = {
    "empty input": ({"input": ""}, "input"),
    "100 KB input": ({"input": "word " * 20_000}, "input"),
    "unknown voice": ({"voice": "alloy"}, "voice"),
    "control character": ({"input": "Hello\x07 there."}, "input"),
    "SSML": ({"input": "<speak>Hello</speak>"}, "input"),
    "mp3": ({"response_format": "mp3"}, "response_format"),
    "speed": ({"speed": 10}, "speed"),
    "speed 0": ({"speed": 0}, "speed"),
    "instructions": ({"instructions": "Speak like a pirate."}, "instructions"),
}


@pytest.mark.parametrize(("fields", "param"), BAD.values(), ids=BAD.keys())
def test_bad_requests_are_400_naming_the_field(api: openai.OpenAI, tts_http: HttpService,
                                               fields: dict[str, object], param: str) -> None:
    request = {"model": MODEL, "voice": "joe", "input": "Hello.", "response_format": "wav",
               **fields}
    with pytest.raises(openai.BadRequestError) as refused:
        api.audio.speech.create(**request)  # type: ignore[arg-type]
    error = refused.value.body
    assert isinstance(error, dict) and error["param"] == param and error["message"]
    assert error["type"] == "invalid_request_error"
    assert tts_http.process.poll() is None
    assert api.audio.speech.create(model=MODEL, voice="espeak", input="Still here.").content


def test_another_model_is_404_and_models_lists_this_one(api: openai.OpenAI) -> None:
    with pytest.raises(openai.NotFoundError):
        api.audio.speech.create(model="tts-1", voice="joe", input="Hello.")
    assert [m.id for m in api.models.list()] == [MODEL]


def test_a_body_that_is_not_json_is_400(tts_http: HttpService) -> None:
    response = httpx.post(f"{tts_http.base_url}/v1/audio/speech", content=b"say hello", timeout=30)
    assert response.status_code == 400
    assert response.json()["error"]["type"] == "invalid_request_error"
