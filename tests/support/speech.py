"""Real synthesized speech for tests (espeak-ng through oricf.audio.synthesize)."""

from __future__ import annotations

from functools import cache

import numpy as np

from oricf.audio import synthesize

QUESTION = "How many people do you see"
QUESTION_WORDS = ("how", "many", "people", "do", "you", "see")


@cache
def speech(text: str, voice: str = "en-us", rate: int = 16000) -> np.ndarray:
    """Mono int16 speech with 200 ms of silence either side, as a microphone would catch it."""
    samples = synthesize(text, voice=voice, sample_rate=rate)
    silence = np.zeros(rate // 5, dtype=np.int16)
    return np.concatenate([silence, samples, silence])


def words(text: str) -> list[str]:
    return "".join(c if c.isalnum() else " " for c in text.lower()).split()
