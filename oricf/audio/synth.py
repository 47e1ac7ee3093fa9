"""Speech synthesized by espeak-ng, for tests, demos and benchmarks."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np

from oricf.audio.pcm import MODEL_RATE


def synthesize(text: str, voice: str = "en-us", rate: int = 160,
               sample_rate: int = MODEL_RATE) -> np.ndarray:
    """Real speech for tests, demos and benchmarks: espeak-ng, converted by sox.

    Returns mono int16 samples at sample_rate. `rate` is espeak-ng's words per minute.
    """
    for tool in ("espeak-ng", "sox"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (run scripts/setup.sh)")
    wav = subprocess.run(["espeak-ng", "-v", voice, "-s", str(rate), "--stdout", text],
                         check=True, capture_output=True).stdout
    raw = subprocess.run(
        ["sox", "-R", "-t", "wav", "-", "-t", "raw", "-r", str(sample_rate), "-c", "1", "-b", "16",
         "-e", "signed-integer", "-L", "-"],
        input=wav, check=True, capture_output=True).stdout
    return np.frombuffer(raw, dtype="<i2").copy()
