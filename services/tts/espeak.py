"""The espeak-ng program: IPA phonemes for Piper voices, and speech of its own voices.

espeak-ng is GPL-3.0. ORICF (Apache-2.0) runs the `espeak-ng` executable as a separate
process, text on its standard input and phonemes or a WAV file on its standard output, and
neither links libespeak-ng nor ships it: the program comes from the system's packages
(Debian `espeak-ng`, installed by scripts/setup.sh). Two programs that talk through pipes
stay separate works (docs/speech-out.md). One process per sentence costs a few milliseconds.
"""

from __future__ import annotations

import logging
import re
import shutil
import subprocess
from collections.abc import Iterator
from typing import Literal

import numpy as np
from pydantic import Field

from oricf.audio import parse_wav
from oricf.config import Schema
from oricf.errors import ConfigError
from oricf.logs import quoted

log = logging.getLogger(__name__)

PROGRAM = "espeak-ng"
TIMEOUT_S = 30.0
DEFAULT_WPM = 175  # espeak-ng's own default speaking rate
MIN_WPM, MAX_WPM = 80, 450  # espeak-ng's range; a speed beyond it is clamped to it
WORD_GAP_UNIT_MS = 10  # espeak-ng's -g counts pauses between words in 10 ms steps
VOICE_NAME = r"^[A-Za-z0-9][A-Za-z0-9_+-]{0,63}$"
# A switch to another language's phonemes inside --ipa output, e.g. "(fr)".
LANGUAGE_SWITCH = re.compile(r"\([a-z]{2,3}(?:-[a-z0-9]+)*\)")


def program() -> str:
    path = shutil.which(PROGRAM)
    if path is None:
        raise ConfigError(f"{PROGRAM} is not installed (Debian package espeak-ng; run "
                          f"scripts/setup.sh)")
    return path


def version() -> str:
    out = _run(["--version"], "")
    return out.decode(errors="replace").split("Data at")[0].strip()


def _run(args: list[str], text: str) -> bytes:
    """The program's output; a failure is its exit status or no output at all. What it says on
    stderr otherwise (its audio library's complaints about a home it cannot write) is logged,
    not fatal: the output does not depend on it."""
    result = subprocess.run([program(), *args], input=text.encode(), capture_output=True,
                            timeout=TIMEOUT_S, check=False)
    said = result.stderr.decode(errors="replace").strip()
    if result.returncode != 0 or not result.stdout:
        raise RuntimeError(f"{PROGRAM} {' '.join(args)} failed ({result.returncode}): "
                           f"{said[:200]}")
    if said:
        log.debug("%s said: %s", PROGRAM, quoted(said))
    return result.stdout


def phonemes(text: str, voice: str) -> list[str]:
    """IPA phonemes of one sentence, a string per clause (espeak-ng ends clauses at commas,
    colons and the like)."""
    out = _run(["-q", "-b", "1", "--ipa", "-v", voice, "--stdin"], text).decode()
    clauses = (LANGUAGE_SWITCH.sub("", line).strip() for line in out.splitlines())
    return [clause for clause in clauses if clause]


def speak(text: str, voice: str, words_per_minute: int, pitch: int, word_gap_ms: int = 0
          ) -> tuple[np.ndarray, int]:
    """Mono int16 samples of the text in an espeak-ng voice, and their sample rate."""
    gap = round(word_gap_ms / WORD_GAP_UNIT_MS)
    wav = _run(["-b", "1", "-v", voice, "-s", str(words_per_minute), "-p", str(pitch),
                "-g", str(gap), "--stdout", "--stdin"], text)
    pcm = parse_wav(wav)
    return pcm.samples.reshape(-1), pcm.sample_rate


def wpm_for(base: int, speed: float) -> int:
    return int(min(MAX_WPM, max(MIN_WPM, round(base * speed))))


class EspeakVoiceConfig(Schema):
    """A voice spoken by espeak-ng itself: light, robotic, any language it knows."""

    engine: Literal["espeak-ng"]
    voice: str = Field("en-us", pattern=VOICE_NAME,
                       description="an espeak-ng voice (`espeak-ng --voices`), e.g. en-us, en-gb")
    words_per_minute: int = Field(DEFAULT_WPM, ge=MIN_WPM, le=MAX_WPM,
                                  description="at speed 1.0")
    pitch: int = Field(50, ge=0, le=99)
    word_gap_ms: int = Field(0, ge=0, le=500, multiple_of=WORD_GAP_UNIT_MS,
                             description="a pause between words; a speech recogniser (or a "
                                         "listener) tells the formant voice's words apart "
                                         "better with one (docs/speech-out.md)")


class EspeakVoice:
    """The espeak-ng engine: the program speaks each sentence itself."""

    def __init__(self, name: str, config: EspeakVoiceConfig) -> None:
        self.name = name
        self.config = config
        self.sample_rate = 0  # the program's, known once loaded
        self.model = f"espeak-ng:{config.voice}"
        self.license = "GPL-3.0-or-later (espeak-ng, run as a separate program)"
        self.sha256 = ""
        self.runtime = PROGRAM

    def load(self) -> None:
        self.runtime = version()
        c = self.config  # the voice exists and speaks; its sample rate is the program's
        try:
            _, self.sample_rate = speak("ready", c.voice, c.words_per_minute, c.pitch,
                                        c.word_gap_ms)
        except RuntimeError as exc:
            raise ConfigError(f"voices.{self.name}: espeak-ng cannot speak with voice "
                              f"'{c.voice}' (see `espeak-ng --voices`): {exc}") from None

    def close(self) -> None:
        pass

    def describe(self) -> dict[str, str]:
        c = self.config
        return {"engine": c.engine, "espeak_voice": c.voice,
                "words_per_minute": str(c.words_per_minute), "pitch": str(c.pitch),
                "word_gap_ms": str(c.word_gap_ms), "sample_rate": str(self.sample_rate)}

    def speak(self, sentence: str, speed: float) -> np.ndarray:
        c = self.config
        samples, rate = speak(sentence, c.voice, wpm_for(c.words_per_minute, speed), c.pitch,
                              c.word_gap_ms)
        if rate != self.sample_rate:
            raise RuntimeError(f"{PROGRAM} changed its sample rate to {rate} Hz")
        return samples

    def pieces(self, sentence: str, speed: float) -> Iterator[np.ndarray]:
        """The sentence whole: espeak-ng makes even a long one in milliseconds."""
        yield self.speak(sentence, speed)
