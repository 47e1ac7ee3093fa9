"""`oricf bench voice`: from the end of a spoken question to the first audio of its answer,
onboard, through the microphone example (configs/pipelines/mic_questions.yaml).

The detector, speech recogniser, language model and speech synthesizer run as `oricf serve`
processes on this machine, the detector counting people in the pedestrian video at the
example's 2 frames/s as context. Questions spoken by espeak-ng are fed at their own pace,
32 ms at a time as a microphone delivers them, into the gateway's own utterance cutter
(Silero VAD, the example's settings), and from there the example's routes run unchanged:
Transcribe, Generate cut into sentences, Synthesize each sentence, the audio out (a WAV
file, or --device: a speaker). Each answer is heard out before the next question.

The time from the end of the question (its last voiced sample pushed) to the first audio
out (the first sentence's audio handed to the output; with --device, the first sample at
the device) is split into stages:

  VAD tail          end of question -> the utterance is cut (min_silence_ms of silence)
  ASR               utterance -> transcript
  LLM 1st sentence  transcript -> the answer's first sentence is complete
  TTS 1st chunk     first sentence -> its audio is out of the synthesizer
  device            (--device) audio handed over -> its first sample at the device

Each voice in --voices is measured in the same run against the same services, the voices
taking turns round by round (a round asks each question once), and so is each end silence
in --min-silence-ms (the utterance cutter's `vad.min_silence_ms`; a question cut in two by
a pause shorter than it is counted as split and left out of the timings). Goal: first audio
within 1.0 s of the end of the question (median) on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from oricf.audio import MODEL_RATE, synthesize
from oricf.bench.common import print_table, served
from oricf.config import config_dir
from oricf.gateway.components import Emitter
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sources.audio_source import Utterances, shared_vad
from oricf.gateway.sources.video_source import VideoSource
from oricf.stats import p90

PIPELINE = config_dir() / "pipelines" / "mic_questions.yaml"
# The last two pause at their comma (160-260 ms as espeak-ng says them), as people do: an end
# silence shorter than such a pause splits them, and the split is counted.
QUESTIONS = ["How many people do you see", "Can you see any people",
             "How many people are there", "Is anyone in front of you",
             "Are there people walking", "Tell me, how many people are in the room",
             "Hey robot, is anyone in front of you"]
STAGES = ("VAD tail", "ASR", "LLM 1st sentence", "TTS 1st chunk", "device")
GOAL_S = 1.0
BLOCK = 512  # samples a microphone block holds at 16 kHz (32 ms)
TURN_TIMEOUT_S = 60.0


@dataclass
class Turn:
    """Clock times (time.monotonic) of one question's way to its first audio."""

    ended: float = 0.0
    utterances: int = 0         # more than one: the cutter split the question
    sound_before: float | None = None  # the speaker's last stream start before the answer
    marks: dict[str, float] = field(default_factory=dict)
    done: threading.Event = field(default_factory=threading.Event)

    def mark(self, name: str) -> None:
        self.marks.setdefault(name, time.monotonic())

    def stages(self) -> dict[str, float] | None:
        order = ["utterance", "transcript", "sentence", "audio", "sound"]
        times = [self.ended] + [self.marks[m] for m in order if m in self.marks]
        if len(times) < 5 or self.utterances > 1:  # a split question answered its first part
            return None
        return dict(zip(STAGES, np.diff(times), strict=False))


class Voice(Emitter):
    """The example pipeline for one voice, its timeline seams, fed like a microphone; its
    pipeline's emitter, marking when the speech leaves for the outlets."""

    def __init__(self, voice: str, addresses: dict[str, str], device: str | None,
                 folder: Path, min_silence_ms: int | None = None) -> None:
        output = ({"audio": {"device": device}} if device
                  else {"wav": str(folder / f"{voice}.wav")})
        sets = [f"endpoints.{name}.address={address}" for name, address in addresses.items()]
        sets += [f"routes.speech.input.audio={folder / 'unused.wav'}",
                 "routes.speech.outputs=[{product: transcript, from: transcript}]",
                 "routes.answer.outputs=[{product: answer_sentence, from: sentence}]",
                 f"routes.voice.call.voice={voice}",
                 f"routes.voice.outputs={json.dumps([{**output, 'from': 'speech'}])}"]
        if min_silence_ms is not None:
            sets.append(f"routes.speech.input.vad.min_silence_ms={min_silence_ms}")
        self.config: PipelineConfig = load_pipeline(PIPELINE, sets=sets)
        self.turn = Turn()
        self.outlets = Outlets(self.config)
        self.pipeline = Pipeline(self.config, self, speaking=self.outlets.speaking)
        for product, mark in (("transcript", "transcript"), ("answer_sentence", "sentence")):
            self.pipeline.products.subscribe(product, lambda _v, m=mark: self.turn.mark(m))
        people = self.config.routes["people"].input
        self.camera = VideoSource("people", people, partial(self.pipeline.submit, "people"),
                                  lambda route: None)
        vad = self.config.routes["speech"].input.vad
        assert vad is not None
        self.cutter = Utterances(shared_vad(), vad)
        self.cutter.begin(MODEL_RATE)

    def emit(self, output: Any, value: Any, record: Any) -> None:
        if output.source == "speech" and "audio" not in self.turn.marks:
            self.turn.mark("audio")
            # Read before the audio is handed over: the speaker's thread may start it at once.
            self.turn.sound_before = _last_start(self._speaker())
            self.outlets.emit(output, value, record)
            self.turn.done.set()  # the route goes on at once, as it does in the gateway
        else:
            self.outlets.emit(output, value, record)

    def _speaker(self) -> Any:
        return next(iter(self.outlets.speakers.values()), None)

    def _await_sound(self, turn: Turn) -> None:
        """The time the answer's first sample reached the device (the speaker's stream
        began to sound), if it did within 5 s."""
        speaker = self._speaker()
        if speaker is None or "audio" not in turn.marks:
            return
        deadline = time.monotonic() + 5
        while _last_start(speaker) == turn.sound_before and time.monotonic() < deadline:
            time.sleep(0.005)
        started = _last_start(speaker)
        if started != turn.sound_before and started is not None:
            turn.marks.setdefault("sound", started)

    def start(self) -> None:
        self.pipeline.start()
        self.camera.start()

    def ask(self, speech: np.ndarray, voiced_end: int) -> Turn:
        """Feeds one question at its own pace; its timeline once its answer is heard."""
        self.turn = turn = Turn()
        started = time.monotonic()
        for offset in range(0, len(speech), BLOCK):
            wait = started + (offset + BLOCK) / MODEL_RATE - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            if offset <= voiced_end < offset + BLOCK:
                turn.ended = time.monotonic()
            for clip in self.cutter.push(speech[offset:offset + BLOCK, None]):
                turn.mark("utterance")
                turn.utterances += 1
                self.pipeline.submit("speech", lambda c=clip: {"audio": c})
        turn.done.wait(TURN_TIMEOUT_S)
        self._await_sound(turn)
        self.pipeline.idle(TURN_TIMEOUT_S)
        for speaker in self.outlets.speakers.values():
            speaker.idle(TURN_TIMEOUT_S)
        return turn

    def close(self) -> None:
        self.camera.stop()
        self.pipeline.stop()
        self.outlets.close()


def _last_start(speaker: Any) -> float | None:
    """When the speaker's latest stream began to sound (None: none yet, or no speaker)."""
    starts = speaker.stats.starts if speaker is not None else ()
    return starts[-1] if starts else None


def spoken_questions() -> list[tuple[np.ndarray, int]]:
    """Each question with 0.5 s of silence before and 1.5 s after; its last voiced sample."""
    questions = []
    for text in QUESTIONS:
        speech = synthesize(text)
        audio = np.concatenate([np.zeros(MODEL_RATE // 2, np.int16), speech,
                                np.zeros(MODEL_RATE * 3 // 2, np.int16)])
        voiced = np.nonzero(np.abs(audio.astype(np.int32)) > 300)[0]
        questions.append((audio, int(voiced[-1])))
    return questions


def summary(turns: list[Turn]) -> dict[str, tuple[float, float]]:
    """Stage -> (median ms, p90 ms); 'total' as well."""
    stages = [s for t in turns if (s := t.stages()) is not None]
    table: dict[str, tuple[float, float]] = {}
    for stage in [*STAGES, "total"]:
        values = [sum(s.values()) if stage == "total" else s[stage]
                  for s in stages if stage == "total" or stage in s]
        if values:
            table[stage] = (float(np.median(values)) * 1000,
                            p90(values) * 1000)
    return table


def report(results: dict[str, list[Turn]]) -> None:
    tables = {voice: summary(turns) for voice, turns in results.items()}
    header = ["stage"]
    for voice in results:
        header += [f"{voice} median ms", "p90 ms", "share"]
    rows = []
    for stage in [*STAGES, "total"]:
        row: list[object] = [stage]
        for table in tables.values():
            median, p90 = table.get(stage, (float("nan"), float("nan")))
            total = table.get("total", (float("nan"), 0))[0]
            row += [f"{median:.0f}", f"{p90:.0f}", f"{median / total:.0%}"]
        if any(stage in table for table in tables.values()):
            rows.append(row)
    counts = ", ".join(f"{v}: {sum(t.stages() is not None for t in ts)}/{len(ts)}, "
                       f"split {sum(t.utterances > 1 for t in ts)}"
                       for v, ts in results.items())
    print_table(f"end of spoken question -> first audio out (answered: {counts})", header,
                rows)
    for voice, table in tables.items():
        median = table.get("total", (float("nan"), 0.0))[0]
        verdict = "met" if median <= GOAL_S * 1000 else "not met"
        print(f"{voice}: median {median:.0f} ms; goal {GOAL_S * 1000:.0f} ms {verdict}")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench voice", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--voices", default="joe,espeak",
                        help="tts voices to compare, comma-separated (default joe,espeak)")
    parser.add_argument("--rounds", type=int, default=2,
                        help="times each question is asked per voice (default 2)")
    parser.add_argument("--min-silence-ms", default="",
                        help="end silences of the utterance cutter to compare, comma-separated "
                        "(default: the example's own vad.min_silence_ms)")
    parser.add_argument("--device", help="play on this audio output device (a speaker, a "
                        "PulseAudio sink) instead of writing a WAV file")
    args = parser.parse_args(argv)
    voices = [v for v in args.voices.split(",") if v]
    silences: list[int | None] = [_silence(v) for v in args.min_silence_ms.split(",") if v]
    if args.rounds < 1:
        raise SystemExit("--rounds: at least 1")
    questions = spoken_questions()
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="oricf-voice-") as scratch:
        addresses = {name: stack.enter_context(served(name))[0]
                     for name in ("detector", "asr", "llm", "tts")}
        variants = [(voice, silence) for voice in voices for silence in silences or [None]]
        results: dict[str, list[Turn]] = {}
        # Round by round, each variant in turn: the machine's load drifts, and so the
        # variants share its ups and downs instead of one getting the busy minutes.
        for _ in range(args.rounds):
            for voice, silence in variants:
                label = voice if silence is None else f"{voice} {silence} ms"
                results.setdefault(label, []).extend(
                    _round(Voice(voice, addresses, args.device, Path(scratch), silence),
                           questions))
    report(results)
    return 0


def _round(run: Voice, questions: list[tuple[np.ndarray, int]]) -> list[Turn]:
    """Each question asked once, after an unmeasured one (the models' first calls)."""
    try:
        run.start()
        time.sleep(2)  # the people count is there
        run.ask(*questions[0])
        return [run.ask(speech, voiced_end) for speech, voiced_end in questions]
    finally:
        run.close()


def _silence(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise SystemExit(f"--min-silence-ms: {text!r} is not a whole number of ms") from None
    if value < 32:
        raise SystemExit(f"--min-silence-ms: {value} is below one VAD window (32 ms)")
    return value
