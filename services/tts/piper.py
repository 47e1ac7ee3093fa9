"""Piper voices (VITS exported to ONNX) on onnxruntime, with phonemes from espeak-ng.

Piper's own runtime (piper-tts 1.x) is GPL-3.0, so ORICF runs the voice's ONNX file itself:
the voice's `.onnx.json` gives the phoneme-to-id table, the sample rate, the espeak-ng voice
and the default scales; the program espeak-ng (espeak.py) gives the IPA phonemes; the ids go
through the network in Piper's layout (start, pad after each phoneme, end).
"""

from __future__ import annotations

import ctypes
import json
import logging
import threading
from collections.abc import Callable, Iterator
from functools import cache
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field

from oricf.config import Schema
from oricf.errors import ConfigError
from oricf.services.tts import espeak
from oricf.services.tts import text as texts

if TYPE_CHECKING:
    from oricf.store import ModelStore

log = logging.getLogger(__name__)

WEIGHTS = "model.onnx"
VOICE_CONFIG = "model.onnx.json"
BOS, EOS, PAD = "^", "$", "_"
SENTENCE_ENDS = ".!?"
MIN_RUN_PHONEMES = 16  # shorter runs would cut single words apart


class PiperVoiceConfig(Schema):
    """A Piper voice from the model store; scales left unset come from its .onnx.json."""

    engine: Literal["piper"]
    model: str = Field(description="catalog name in configs/models.yaml, e.g. piper-joe-medium")
    threads: int = Field(2, ge=1, le=64, description="onnxruntime intra-op threads")
    parallel: int = Field(
        1, ge=1, le=16, description="runs of the network made at once; each holds the "
                                    "decoder's activations, about 20-35 MB per second of its "
                                    "audio")
    max_run_phonemes: int = Field(
        200, ge=MIN_RUN_PHONEMES, le=5000,
        description="phonemes the network is given at once at speed 1 and length_scale 1 "
                    "(fewer in proportion when slower): a sentence with more is spoken in runs "
                    "cut between clauses, else between words; the decoder holds about 20 MB "
                    "per second of a run's audio")
    noise_scale: float | None = Field(None, ge=0, le=2, description="voice variation")
    length_scale: float | None = Field(None, gt=0, le=4, description=">1 speaks slower")
    noise_w: float | None = Field(None, ge=0, le=2, description="phoneme length variation")


class PiperVoice:
    def __init__(self, name: str, config: PiperVoiceConfig, store: ModelStore) -> None:
        self.name = name
        self.config = config
        entry = store.entry(config.model)
        self.weights = store.path(config.model, WEIGHTS)
        self.voice_config = store.path(config.model, VOICE_CONFIG)
        self.model = config.model
        self.license = entry.license
        self.sha256 = next(f.sha256 for f in entry.files if f.name == WEIGHTS)
        self.runtime = "onnxruntime"
        self.sample_rate = 0
        self.espeak_voice = ""
        self._ids: dict[str, int] = {}
        self._scales = np.zeros(3, dtype=np.float32)
        self._session: Any = None
        self._turns = threading.BoundedSemaphore(config.parallel)

    def load(self) -> None:
        import onnxruntime as ort

        self._read_voice_config()
        options = ort.SessionOptions()
        options.intra_op_num_threads = self.config.threads
        options.inter_op_num_threads = 1
        # Without the arena each run's activations (hundreds of MB for a long sentence) go
        # back when it ends; with it the process kept its largest run's memory for good.
        options.enable_cpu_mem_arena = False
        # Idle intra-op threads sleep instead of spinning between the decoder's many small
        # operators: on a robot's few cores a spinning thread takes the core that the
        # language model (still finishing the answer) or the other services need, and the
        # sentence then waits for it.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        self._session = ort.InferenceSession(str(self.weights), options,
                                             providers=["CPUExecutionProvider"])
        self.runtime = f"onnxruntime {ort.__version__} + {espeak.version()}"
        self.speak("Ready.", 1.0)  # the first run allocates onnxruntime's buffers

    def _read_voice_config(self) -> None:
        where = f"{self.model}/{VOICE_CONFIG}"
        try:
            voice = json.loads(self.voice_config.read_text())
            self.sample_rate = int(voice["audio"]["sample_rate"])
            self.espeak_voice = str(voice["espeak"]["voice"])
            self._ids = {p: int(ids[0]) for p, ids in voice["phoneme_id_map"].items()}
            inference = voice.get("inference", {})
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            raise ConfigError(f"{where}: not a Piper voice config ({exc})") from None
        if voice.get("phoneme_type", "espeak") != "espeak" or voice.get("num_speakers", 1) != 1:
            raise ConfigError(f"{where}: only one-speaker voices with espeak phonemes are run")
        c = self.config
        self._scales = np.array([
            c.noise_scale if c.noise_scale is not None else inference.get("noise_scale", 0.667),
            c.length_scale if c.length_scale is not None else inference.get("length_scale", 1.0),
            c.noise_w if c.noise_w is not None else inference.get("noise_w", 0.8)],
            dtype=np.float32)

    def close(self) -> None:
        self._session = None

    def describe(self) -> dict[str, str]:
        noise, length, noise_w = (f"{v:g}" for v in self._scales)
        return {"engine": "piper", "model": self.model, "espeak_voice": self.espeak_voice,
                "sample_rate": str(self.sample_rate), "threads": str(self.config.threads),
                "parallel": str(self.config.parallel),
                "noise_scale": noise, "length_scale": length, "noise_w": noise_w}

    def phoneme_ids(self, text: str) -> list[int]:
        """Piper's input for phonemes text: each phoneme's id followed by the pad id,
        between the start and end ids."""
        ids, pad = [self._ids[BOS], self._ids[PAD]], self._ids[PAD]
        for phoneme in text:
            if phoneme in self._ids:  # marks the voice was not trained on are left out
                ids += [self._ids[phoneme], pad]
        ids.append(self._ids[EOS])
        return ids

    def runs(self, sentence: str, speed: float) -> list[str]:
        """The sentence's phonemes as the texts of the network's runs: its clauses joined by
        commas, the sentence's own end mark kept, in runs of at most run_phonemes(speed)
        phonemes, cut between clauses, else between words."""
        clauses = espeak.phonemes(sentence, self.espeak_voice)
        end = sentence[-1] if sentence[-1] in SENTENCE_ENDS else "."
        pieces = texts.cut(", ".join(clauses), self.run_phonemes(speed)) or [""]
        last = len(pieces) - 1
        return [piece.rstrip(",") + ("," if i < last else end) for i, piece in enumerate(pieces)]

    def run_phonemes(self, speed: float) -> int:
        """The most phonemes of one run at this speed: a run's audio, and the decoder's
        memory with it, grows with its phonemes times length_scale / speed."""
        stretch = float(self._scales[1]) / speed
        return max(MIN_RUN_PHONEMES, int(self.config.max_run_phonemes / max(stretch, 1e-3)))

    def speak(self, sentence: str, speed: float) -> np.ndarray:
        return np.concatenate(list(self.pieces(sentence, speed)))

    def pieces(self, sentence: str, speed: float) -> Iterator[np.ndarray]:
        for text in self.runs(sentence, speed):
            yield self._run(text, speed)

    def _run(self, text: str, speed: float) -> np.ndarray:
        session = self._session
        if session is None:
            raise RuntimeError(f"voice {self.name} is not loaded")
        ids = np.array([self.phoneme_ids(text)], dtype=np.int64)
        scales = self._scales.copy()
        scales[1] /= speed
        with self._turns:  # concurrent calls take turns run by run
            audio = session.run(None, {"input": ids,
                                       "input_lengths": np.array([ids.shape[1]], dtype=np.int64),
                                       "scales": scales})[0]
            _give_back_freed_memory()
        return (np.clip(audio.reshape(-1), -1.0, 1.0) * 32767).astype(np.int16)


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim  # type: ignore[no-any-return]
    except (OSError, AttributeError):  # not glibc: its allocator keeps no such arenas
        return None


def _give_back_freed_memory() -> None:
    """Returns the run's freed activations to the system. glibc keeps what onnxruntime's
    threads free in their own arenas; the next run's allocations land beside it, and the
    peak of a request made of many runs grew run by run (one of 26 runs peaked 306-568 MB
    above its start, 399-422 MB with this)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)

