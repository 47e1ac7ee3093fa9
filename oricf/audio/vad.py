"""Streaming voice-activity detection: the Silero VAD v6 ONNX file from the faster-whisper wheel.

The model scores 512-sample windows of 16 kHz audio (32 ms). Each call takes the window
with the 64 samples before it in front ([1, 576]), plus the LSTM state h and c
([1, 1, 128] each), and returns the speech probability and the next state. One
onnxruntime session serves every stream (sessions are thread-safe); each stream keeps its
own state in a VadStream.
"""

from __future__ import annotations

import importlib.resources
import logging
from pathlib import Path
from typing import Any

import numpy as np

from oricf.errors import ConfigError, ModelMissing, NotReady

log = logging.getLogger(__name__)

SAMPLE_RATE = 16000
WINDOW = 512
CONTEXT = 64
STATE_SHAPE = (1, 1, 128)
ASSET = "silero_vad_v6.onnx"
EXPECTED_INPUTS = ("input", "h", "c")


def vad_model_path() -> Path:
    """The ONNX file inside the installed faster-whisper package."""
    try:
        assets = importlib.resources.files("faster_whisper") / "assets" / ASSET
    except ModuleNotFoundError:
        raise ModelMissing("faster-whisper is not installed (pip install 'oricf[asr]')") from None
    path = Path(str(assets))
    if not path.is_file():
        raise ModelMissing(f"{path} is missing from the faster-whisper package")
    return path


class SileroVad:
    """The shared session: load() once, then stream() per audio stream."""

    def __init__(self, threads: int = 1) -> None:
        self.threads = threads
        self.path: Path | None = None
        self.runtime = "onnxruntime"
        self._session: Any = None

    def load(self) -> None:
        import onnxruntime as ort

        self.path = vad_model_path()
        options = ort.SessionOptions()
        options.intra_op_num_threads = self.threads
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        session = ort.InferenceSession(str(self.path), options,
                                       providers=["CPUExecutionProvider"])
        names = tuple(i.name for i in session.get_inputs())
        if names != EXPECTED_INPUTS:
            raise ConfigError(f"{self.path}: unexpected VAD inputs {names} "
                              f"(expected {EXPECTED_INPUTS}); faster-whisper version changed?")
        self.runtime = f"onnxruntime {ort.__version__}"
        self._session = session

    def close(self) -> None:
        self._session = None

    def stream(self) -> VadStream:
        if self._session is None:
            raise NotReady("the voice-activity detector is not loaded")
        return VadStream(self._session)


class VadStream:
    """Speech probability of consecutive 512-sample windows of one stream."""

    def __init__(self, session: Any) -> None:
        self._session = session
        self._h = np.zeros(STATE_SHAPE, dtype=np.float32)
        self._c = np.zeros(STATE_SHAPE, dtype=np.float32)
        self._context = np.zeros(CONTEXT, dtype=np.float32)

    def probability(self, window: np.ndarray) -> float:
        """Speech probability of the next window (float32, exactly WINDOW samples)."""
        if window.shape != (WINDOW,):
            raise ValueError(f"a VAD window is {WINDOW} samples, got {window.shape}")
        frame = np.concatenate([self._context, window]).astype(np.float32, copy=False)[None]
        prob, self._h, self._c = self._session.run(
            None, {"input": frame, "h": self._h, "c": self._c})
        self._context = window[-CONTEXT:]
        return float(np.asarray(prob).reshape(-1)[0])
