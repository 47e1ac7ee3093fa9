"""`oricf bench tts`: time to first audio, real-time factor and intelligibility of each voice of
the speech-synthesis service, side by side in one run.

One real `oricf serve tts` process with the shipped config (the Piper voice `joe` and the
espeak-ng voice `espeak`) answers SynthesizeStream for short answers (one sentence) and long
ones (four to six sentences), voice after voice for each answer, so both see the same
machine load. Time to first audio is the client's time from the call to the first sentence's
audio; the real-time factor is the whole answer's synthesis time over its audio's length
(below 1: faster than it is spoken). Each answer's audio is then transcribed by `oricf serve
asr` (Whisper) and the word error rate against the answer is reported (numbers compared as
words).
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import ExitStack
from dataclasses import dataclass, field

import grpc

from oricf.bench.asr import word_errors
from oricf.bench.common import median_ms, print_table, served
from oricf.services.tts.text import normalise
from oricf.stats import p90
from oricf.v1 import speech_pb2, speech_pb2_grpc, synthesis_pb2, synthesis_pb2_grpc

SHORT = [
    "I can see 3 people.",
    "There are 2 people near the door.",
    "The box is 12.5 m away.",
    "The battery is at 80%.",
    "Turn left in 5 seconds.",
    "My 1st task is to find 7 red boxes.",
]
LONG = [
    "I can see 3 people in the room. Two of them are sitting at the table. The third one is "
    "standing near the window. Nobody is moving right now.",
    "The battery is at 45%. That is enough for about 2 hours of driving. The charging "
    "station is 12 m away. Shall I go there now? I will wait for your answer.",
    "I counted 15 cups on the shelf. 4 of them are red and 11 are blue. The shelf is 1.5 m "
    "high. I can reach the lower 2 rows. The top row is too high for me. Please tell me "
    "which cup to bring.",
]
VOICES = ["joe", "espeak"]
SPELLINGS = {"metres": "meters"}  # Whisper spells some words either way


def words(text: str) -> list[str]:
    spoken = normalise(text).lower().replace("-", " ")
    cleaned = "".join(c if c.isalnum() or c == "'" else " " for c in spoken)
    return [SPELLINGS.get(w, w) for w in cleaned.split()]


@dataclass
class Results:
    voice: str
    kind: str
    first_audio_s: list[float] = field(default_factory=list)
    synthesis_s: float = 0.0
    audio_s: float = 0.0
    errors: int = 0
    words: int = 0

    @property
    def rtf(self) -> float:
        return self.synthesis_s / max(self.audio_s, 1e-9)

    @property
    def wer(self) -> float:
        return self.errors / max(self.words, 1)


def speak(stub: synthesis_pb2_grpc.SpeechSynthesizerStub, text: str,
          voice: str) -> tuple[float, float, float, bytes, int]:
    """(first audio s, total s, audio s, pcm, rate) of one streamed answer."""
    started = time.perf_counter()
    first = 0.0
    audio_s = 0.0
    pcm = b""
    rate = 0
    request = synthesis_pb2.SynthesizeRequest(text=text, voice=voice)
    for chunk in stub.SynthesizeStream(request, timeout=120):
        if not pcm:
            first = time.perf_counter() - started
        pcm += chunk.audio.data
        rate = chunk.audio.sample_rate
        audio_s += chunk.duration_s
    return first, time.perf_counter() - started, audio_s, pcm, rate


def transcribe(stub: speech_pb2_grpc.SpeechRecognizerStub, pcm: bytes, rate: int) -> str:
    audio = speech_pb2.Audio(data=pcm, encoding="pcm_s16le", sample_rate=rate)
    return stub.Transcribe(speech_pb2.TranscribeRequest(audio=audio), timeout=120).text


def run(tts: synthesis_pb2_grpc.SpeechSynthesizerStub,
        asr: speech_pb2_grpc.SpeechRecognizerStub | None, voices: list[str],
        rounds: int) -> list[Results]:
    results = {(v, kind): Results(v, kind) for kind in ("short", "long") for v in voices}
    for voice in voices:  # warm-up, not measured
        speak(tts, SHORT[0], voice)
    for _ in range(rounds):
        for kind, answers in (("short", SHORT), ("long", LONG)):
            for answer in answers:
                for voice in voices:
                    first, total, audio_s, pcm, rate = speak(tts, answer, voice)
                    r = results[(voice, kind)]
                    r.first_audio_s.append(first)
                    r.synthesis_s += total
                    r.audio_s += audio_s
                    if asr is not None:
                        reference = words(answer)
                        r.errors += word_errors(reference, words(transcribe(asr, pcm, rate)))
                        r.words += len(reference)
    return list(results.values())


def report(results: list[Results], with_wer: bool) -> None:
    base = {r.kind: r for r in results if r.voice == results[0].voice}
    rows = []
    for r in results:
        ratio = median_ms(r.first_audio_s) / median_ms(base[r.kind].first_audio_s)
        rows.append([r.voice, r.kind, str(len(r.first_audio_s)),
                     f"{median_ms(r.first_audio_s):.0f}", f"{p90(r.first_audio_s) * 1e3:.0f}",
                     f"{ratio:.2f}x", f"{r.rtf:.3f}", f"{r.audio_s / len(r.first_audio_s):.1f}",
                     f"{r.wer:.1%}" if with_wer else "-"])
    print_table("SynthesizeStream, voices interleaved answer by answer",
                ["voice", "answers", "n", "first audio ms (median)", "p90 ms",
                 "first audio ratio", "RTF", "audio s/answer", "WER"], rows)
    print(f"\nspread of the short answers' first audio: "
          f"{statistics.pstdev(base['short'].first_audio_s) * 1e3:.0f} ms "
          f"(stdev, {results[0].voice})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench tts", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--target", help="bench a running tts service at HOST:PORT instead")
    parser.add_argument("--voices", nargs="+", default=VOICES, help="declared voices")
    parser.add_argument("--rounds", type=int, default=2, help="passes over the answers")
    parser.add_argument("--no-wer", action="store_true",
                        help="skip transcribing the audio (no speech-recognition service)")
    args = parser.parse_args(argv)
    with ExitStack() as stack:
        tts_address = args.target or stack.enter_context(served("tts"))[0]
        tts = synthesis_pb2_grpc.SpeechSynthesizerStub(
            stack.enter_context(grpc.insecure_channel(tts_address)))
        asr = None
        if not args.no_wer:
            asr_address = stack.enter_context(served("asr"))[0]
            asr = speech_pb2_grpc.SpeechRecognizerStub(
                stack.enter_context(grpc.insecure_channel(asr_address)))
        results = run(tts, asr, args.voices, args.rounds)
    report(results, not args.no_wer)
    return 0
