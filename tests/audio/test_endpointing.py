"""Voice-activity endpointing with the real Silero VAD on real speech."""

from collections.abc import Iterator
from itertools import pairwise

import numpy as np
import pytest

from oricf.audio import EndpointingSettings, synthesize, to_float32
from oricf.audio.endpointing import Endpointer, Utterance
from oricf.audio.vad import WINDOW, SileroVad

RATE = 16000


@pytest.fixture(scope="module")
def vad() -> Iterator[SileroVad]:
    detector = SileroVad()
    detector.load()
    yield detector
    detector.close()


@pytest.fixture(scope="module")
def question() -> np.ndarray:
    return to_float32(synthesize("How many people do you see"))


def voiced_span(samples: np.ndarray) -> tuple[int, int]:
    """First and last sample that is clearly not silence."""
    loud = np.flatnonzero(np.abs(samples) > 0.02)
    return int(loud[0]), int(loud[-1])


def run(vad: SileroVad, audio: np.ndarray, sizes: list[int] | None = None,
        **settings: float) -> list[Utterance]:
    endpointer = Endpointer(vad.stream(), EndpointingSettings(**settings))
    found: list[Utterance] = []
    offset, turn = 0, 0
    while offset < len(audio):
        size = sizes[turn % len(sizes)] if sizes else len(audio)
        found += endpointer.push(audio[offset:offset + size])
        offset, turn = offset + size, turn + 1
    return found + endpointer.flush()


def test_speech_is_found_with_its_pad_and_a_click_is_dropped(
        vad: SileroVad, question: np.ndarray) -> None:
    click = np.random.default_rng(0).standard_normal(1600).astype(np.float32) * 0.3
    lead = RATE // 2 + len(click) + RATE
    audio = np.concatenate([np.zeros(RATE // 2, np.float32), click, np.zeros(RATE, np.float32),
                            question, np.zeros(RATE, np.float32)])
    (utterance,) = run(vad, audio)
    first, last = voiced_span(question)
    pad = 200 * RATE // 1000
    # The utterance covers the speech and starts at most one pad (plus a window) before it.
    # It ends one pad after the VAD's probability falls, which lags the sound by a few windows.
    assert lead + first - pad - WINDOW <= utterance.start <= lead + first
    assert lead + last - 2 * WINDOW <= utterance.end <= lead + last + pad + 4 * WINDOW
    np.testing.assert_array_equal(audio[utterance.start:utterance.end], utterance.samples)
    assert utterance.vad_ms > 0


def test_chunk_sizes_do_not_matter(vad: SileroVad, question: np.ndarray) -> None:
    audio = np.concatenate([np.zeros(RATE // 3, np.float32), question,
                            np.zeros(RATE, np.float32), question, np.zeros(RATE, np.float32)])
    whole = run(vad, audio)
    pieces = run(vad, audio, sizes=[1, 333, 512, 1000, 7])
    assert len(whole) == len(pieces) == 2
    for a, b in zip(whole, pieces, strict=True):
        assert a.start == b.start
        np.testing.assert_array_equal(a.samples, b.samples)


def test_flush_ends_an_open_utterance(vad: SileroVad, question: np.ndarray) -> None:
    audio = np.concatenate([np.zeros(RATE // 2, np.float32), question[:RATE]])
    (utterance,) = run(vad, audio)
    assert utterance.end == len(audio)


def test_long_speech_is_cut_into_contiguous_pieces(vad: SileroVad, question: np.ndarray) -> None:
    first, last = voiced_span(question)
    talk = np.concatenate([question[first:last]] * 4)
    pieces = run(vad, np.concatenate([talk, np.zeros(RATE, np.float32)]), max_utterance_s=2.0)
    assert len(pieces) >= 3
    assert all(len(p.samples) <= 2 * RATE for p in pieces)
    for before, after in pairwise(pieces):
        assert after.start == before.end   # nothing lost, nothing repeated at a cut


def test_silence_gives_nothing(vad: SileroVad) -> None:
    assert run(vad, np.zeros(3 * RATE, np.float32)) == []
