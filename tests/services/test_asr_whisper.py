"""The faster-whisper back end itself: the short encoder window, its fallback, the full one."""

from collections.abc import Iterator

import numpy as np
import pytest

from oricf.audio import synthesize, to_float32
from oricf.errors import InvalidInput, NotReady
from oricf.services.asr.recognizer import AsrModelSettings
from oricf.services.asr.short_window import ShortWindowDecoder, ends_in_a_loop
from oricf.services.asr.whisper import WhisperRecognizer
from oricf.store import ModelStore
from tests.support.speech import QUESTION, QUESTION_WORDS, words


def recognizer(**options: object) -> WhisperRecognizer:
    return WhisperRecognizer(AsrModelSettings(options=options), ModelStore())


@pytest.fixture(scope="module")
def whisper() -> Iterator[WhisperRecognizer]:
    model = recognizer()
    model.load()
    yield model
    model.close()


@pytest.fixture(scope="module")
def question() -> np.ndarray:
    pad = np.zeros(3200, np.float32)
    return np.concatenate([pad, to_float32(synthesize(QUESTION)), pad])


@pytest.mark.parametrize(("text", "looping"), [
    ("Move back. Move back.", True),
    ("Go-O-O-O-O", True),
    ("no no no", True),
    ("turn left turn left turn left", True),
    ("Stop stop", False),            # a word said twice is speech
    ("it is what it is", False),
    ("How many people do you see?", False),
    ("", False),
])
def test_loops_are_spotted(text: str, looping: bool) -> None:
    assert ends_in_a_loop(text) is looping


def test_window_is_four_times_the_audio_within_bounds(whisper: WhisperRecognizer,
                                                     question: np.ndarray) -> None:
    decoder = whisper._short_decoder("en")
    assert decoder.window_frames(100) == 1000     # 1 s of audio: the 10 s minimum
    assert decoder.window_frames(500) == 2000     # 5 s of audio: 20 s window
    assert decoder.window_frames(750) is None     # would be 30 s: the full path instead
    text = decoder.decode(question)
    assert text is not None and set(QUESTION_WORDS) <= set(words(text)), text


def test_long_audio_takes_the_full_window(whisper: WhisperRecognizer,
                                          question: np.ndarray) -> None:
    long_audio = np.concatenate([question] * 5)   # about 10 s
    assert whisper._short_decoder("en").decode(long_audio) is None
    result = whisper.transcribe(long_audio, "en")
    assert words(result.text).count("people") >= 4, result.text
    assert result.duration_s == pytest.approx(len(long_audio) / 16000)


def test_a_loop_falls_back_to_the_full_window(whisper: WhisperRecognizer,
                                             question: np.ndarray) -> None:
    decoder = ShortWindowDecoder(whisper._model, "en", beam_size=1, min_window_s=5,
                                 no_speech_threshold=0.6, initial_prompt=None,
                                 window_per_audio=2)
    # A 5 s window around 2.3 s of audio is too full: Whisper repeats itself, and the
    # decoder refuses its own result rather than return it.
    assert decoder.decode(question) is None


def test_silence_and_noise_give_no_text(whisper: WhisperRecognizer) -> None:
    assert whisper.transcribe(np.zeros(16000, np.float32), "en").text == ""
    noise = np.random.default_rng(0).standard_normal(32000).astype(np.float32) * 0.05
    assert whisper.transcribe(noise, "en").text == ""


def test_full_window_alone_gives_the_same_words(question: np.ndarray) -> None:
    model = recognizer(short_window=False, beam_size=2)
    model.load()
    try:
        result = model.transcribe(question, "en")
        assert set(QUESTION_WORDS) <= set(words(result.text)), result.text
        assert model.info().parameters["short_window"] == "False"
        assert model.info().parameters["beam_size"] == "2"
    finally:
        model.close()


def test_language_and_lifecycle_errors(question: np.ndarray) -> None:
    model = recognizer()
    with pytest.raises(NotReady):
        model.transcribe(question, "en")
    model.load()
    assert model.languages() == ["en"]
    with pytest.raises(InvalidInput, match="language 'fr' is not supported"):
        model.transcribe(question, "fr")
    model.close()
    with pytest.raises(NotReady):
        model.transcribe(question, "en")
