"""Whisper on a window shorter than 30 s: the fast path for short spoken queries.

faster-whisper always pads the audio's features to Whisper's 30 s window, and the encoder's
cost grows faster than linearly with the window. CTranslate2 accepts shorter windows.
Whisper keeps its accuracy while the audio fills at most about a quarter of the window;
fuller windows make it repeat itself instead of ending. So the window is 4x the audio and at
least `min_window_s`, and a result that looks repetitive, or has more tokens than speech of
that length could have, returns None: the caller then decodes again with the full window (as
faster-whisper's own fallback does). `oricf bench asr` compares it with the full window
(docs/benchmarks.md).
"""

from __future__ import annotations

import logging
import math
import re
import zlib
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

FULL_WINDOW_FRAMES = 3000      # 30 s of 10 ms mel frames
WINDOW_PER_AUDIO = 4           # window = 4x the audio
# faster-whisper's defaults for spotting a failed decode and for silence.
COMPRESSION_RATIO_LIMIT = 2.4
LOG_PROB_THRESHOLD = -1.0
# Speech makes about 4 tokens a second; more than this budget means Whisper is looping.
TOKENS_PER_SECOND = 8
MIN_TOKENS = 8


def compression_ratio(text: str) -> float:
    data = text.encode("utf-8")
    return len(data) / len(zlib.compress(data)) if data else 0.0


def ends_in_a_loop(text: str) -> bool:
    """True when the words end in one word said 3+ times or a phrase said 2+ times.

    Too short for the compression ratio to see ("Move back. Move back.", "Go-o-o-o").
    A false alarm only costs a second decode with the full window.
    """
    words = re.sub(r"[^\w']+", " ", text.lower()).split()
    for unit in range(1, len(words) // 2 + 1):
        tail = words[-unit:]
        count = 1
        while words[-(count + 1) * unit:len(words) - count * unit] == tail:
            count += 1
        if count >= (3 if unit == 1 else 2):
            return True
    return False


class ShortWindowDecoder:
    """Greedy or beam decoding of one short clip; built once the model is loaded."""

    def __init__(self, model: Any, language: str, beam_size: int, min_window_s: float,
                 no_speech_threshold: float | None, initial_prompt: str | None,
                 window_per_audio: int = WINDOW_PER_AUDIO) -> None:
        from faster_whisper.tokenizer import Tokenizer
        from faster_whisper.transcribe import get_suppressed_tokens

        self.model = model
        self.tokenizer = Tokenizer(model.hf_tokenizer, model.model.is_multilingual,
                                   task="transcribe", language=language)
        previous = self.tokenizer.encode(" " + initial_prompt.strip()) if initial_prompt else []
        self.prompt = model.get_prompt(self.tokenizer, previous, without_timestamps=True)
        self.suppress = list(get_suppressed_tokens(self.tokenizer, [-1]))
        self.beam_size = beam_size
        self.min_frames = int(min_window_s * 100)
        self.window_per_audio = window_per_audio
        self.no_speech_threshold = no_speech_threshold

    def window_frames(self, frames: int) -> int | None:
        """The window for audio of `frames` mel frames; None when only the full one fits."""
        window = max(self.min_frames, self.window_per_audio * frames)
        return window if window < FULL_WINDOW_FRAMES else None

    def decode(self, samples: np.ndarray) -> str | None:
        """The text, "" for silence, or None when the short window cannot be trusted."""
        import ctranslate2
        from faster_whisper.audio import pad_or_trim

        extractor = self.model.feature_extractor
        window = self.window_frames(len(samples) // extractor.hop_length + 1)
        if window is None:
            return None
        features = extractor(samples)
        padded = np.ascontiguousarray(pad_or_trim(features, window)[np.newaxis])
        duration_s = len(samples) / extractor.sampling_rate
        budget = MIN_TOKENS + math.ceil(TOKENS_PER_SECOND * duration_s)
        # CTranslate2 4.8 was seen stopping Whisper at about half of max_length; twice the
        # budget lets a loop run past the budget (and be seen) however max_length counts.
        result = self.model.model.generate(
            ctranslate2.StorageView.from_array(padded), [self.prompt],
            beam_size=self.beam_size, max_length=len(self.prompt) + 2 * budget,
            return_scores=True, return_no_speech_prob=True, suppress_blank=True,
            suppress_tokens=self.suppress)[0]
        tokens = result.sequences_ids[0]
        text = self.tokenizer.decode(tokens).strip()
        avg_log_prob = result.scores[0] * len(tokens) / (len(tokens) + 1)
        threshold = self.no_speech_threshold
        if threshold is not None and result.no_speech_prob > threshold \
                and avg_log_prob < LOG_PROB_THRESHOLD:
            return ""
        if len(tokens) > budget or ends_in_a_loop(text) \
                or compression_ratio(text) > COMPRESSION_RATIO_LIMIT:
            log.debug("short window of %d frames failed (%r); using the full window",
                      window, text[:80])
            return None
        return text
