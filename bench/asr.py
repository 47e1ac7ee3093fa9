"""`oricf bench asr`: word error rate and latency of the speech service on spoken robot queries.

Queries are synthesized with espeak-ng in two voices, each padded with 200 ms of silence
either side (what the stream's endpointing hands the model). Every query goes through
Transcribe on a real `oricf serve asr` process with the shipped config; in the same run,
interleaved query by query, processes with variants of it are measured for comparison:
Whisper's full 30 s encoder window instead of the short one, and greedy decoding (beam 1).
Latency is the client's round trip. Targets: WER at most 15%, median latency at most
0.6 s per query.
"""

from __future__ import annotations

import argparse
import re
import statistics
import tempfile
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import grpc
import numpy as np

from oricf.audio import MODEL_RATE, synthesize
from oricf.bench.common import median_ms, print_table, served, variant_config
from oricf.bench.protocols import parse_protocols
from oricf.v1 import speech_pb2, speech_pb2_grpc

QUERIES = [
    "How many people do you see",
    "Is anyone in the room",
    "Stop moving and turn left",
    "What do you see in front of you",
    "Go to the kitchen and wait there",
    "How many chairs are in the hallway",
    "Turn right and drive forward two meters",
    "Please bring me a cup of water",
    "Are there any people near the door",
    "Follow me to the charging station",
    "Count the people in the picture",
    "What is the battery level",
]
VOICES = ["en-us", "en-gb"]
TARGET_WER = 0.15
TARGET_LATENCY_MS = 600.0
VARIANTS: dict[str, dict[str, Any]] = {
    "full 30 s window": {"model": {"options": {"short_window": False}}},
    "greedy (beam 1)": {"model": {"options": {"beam_size": 1}}},
}

ONES = ["zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
        "eleven", "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen",
        "eighteen", "nineteen"]
TENS = ["", "", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety"]


def number_words(value: int) -> str:
    """0-999 in words, the way the queries would be written out."""
    if value < 20:
        return ONES[value]
    if value < 100:
        tens, ones = divmod(value, 10)
        return TENS[tens] + (f" {ONES[ones]}" if ones else "")
    hundreds, rest = divmod(value, 100)
    return f"{ONES[hundreds]} hundred" + (f" {number_words(rest)}" if rest else "")


def normalise(text: str) -> list[str]:
    """Words to compare: the reference and the transcript differ in form, not content, when
    only case, punctuation or "2" versus "two" differ, so those are made equal; hyphens split
    words ("twenty-one" -> "twenty one"); numbers above 999 stay digits."""
    text = re.sub(r"\d+", lambda m: number_words(int(m.group()))
                  if int(m.group()) < 1000 else m.group(), text.lower())
    return re.sub(r"[^a-z0-9' ]+", " ", text.replace("-", " ")).split()


def word_errors(reference: list[str], hypothesis: list[str]) -> int:
    """Substitutions + deletions + insertions (Levenshtein distance over words)."""
    row = list(range(len(hypothesis) + 1))
    for i, ref in enumerate(reference, 1):
        previous, row[0] = row[0], i
        for j, hyp in enumerate(hypothesis, 1):
            previous, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1, previous + (ref != hyp))
    return row[-1]


@dataclass
class Results:
    name: str
    errors: int = 0
    words: int = 0
    latency_s: list[float] = field(default_factory=list)
    inference_ms: list[float] = field(default_factory=list)

    @property
    def wer(self) -> float:
        return self.errors / max(self.words, 1)


@dataclass(frozen=True)
class Query:
    text: str
    voice: str
    pcm: bytes


def make_queries(voices: list[str]) -> list[Query]:
    pad = np.zeros(MODEL_RATE // 5, dtype=np.int16)
    return [Query(text, voice, np.concatenate([pad, synthesize(text, voice=voice), pad])
                  .astype("<i2").tobytes())
            for voice in voices for text in QUERIES]


def transcribe(stub: speech_pb2_grpc.SpeechRecognizerStub, query: Query,
               results: Results) -> str:
    request = speech_pb2.TranscribeRequest(audio=speech_pb2.Audio(
        data=query.pcm, encoding="pcm_s16le", sample_rate=MODEL_RATE))
    started = time.perf_counter()
    transcript = stub.Transcribe(request, timeout=30)
    results.latency_s.append(time.perf_counter() - started)
    results.inference_ms.append(transcript.timings.inference_ms)
    reference = normalise(query.text)
    results.errors += word_errors(reference, normalise(transcript.text))
    results.words += len(reference)
    return transcript.text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench asr", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--target", help="bench a running service at HOST:PORT instead "
                                         "(no comparison)")
    parser.add_argument("--voices", nargs="+", default=VOICES, help="espeak-ng voices")
    parser.add_argument("--rounds", type=int, default=1, help="passes over the queries")
    parser.add_argument("--protocol", type=parse_protocols, metavar="grpc,openai",
                        help="instead: latency over these protocols side by side "
                             "(bench/protocols.py)")
    args = parser.parse_args(argv)
    if args.protocol:
        from oricf.bench.asr_protocols import compare

        return compare(args, make_queries(args.voices),
                       lambda q, text: word_errors(normalise(q.text), normalise(text)),
                       lambda q: len(normalise(q.text)))

    queries = make_queries(args.voices)
    with ExitStack() as stack:
        addresses = {"shipped": args.target or stack.enter_context(served("asr"))[0]}
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="oricf-bench-")))
        for i, (name, overrides) in enumerate(({} if args.target else VARIANTS).items()):
            path = variant_config("asr", overrides, folder, f"variant{i}")
            addresses[name] = stack.enter_context(served("asr", "--config", str(path)))[0]
        channels = [stack.enter_context(grpc.insecure_channel(a)) for a in addresses.values()]
        stubs = {name: speech_pb2_grpc.SpeechRecognizerStub(c)
                 for name, c in zip(addresses, channels, strict=True)}
        results = run(queries, stubs, args.rounds)
    report(results)
    return 0


def run(queries: list[Query], stubs: dict[str, speech_pb2_grpc.SpeechRecognizerStub],
        rounds: int) -> list[Results]:
    results = {name: Results(name) for name in stubs}
    for stub in stubs.values():  # warm-up, not measured
        transcribe(stub, queries[0], Results("warm-up"))
    rows = []
    for _ in range(rounds):
        for query in queries:
            texts = {name: transcribe(stub, query, results[name]) for name, stub in stubs.items()}
            first = next(iter(results.values()))
            hypothesis = texts[first.name]
            rows.append([query.voice, query.text, hypothesis,
                         word_errors(normalise(query.text), normalise(hypothesis)),
                         f"{first.latency_s[-1] * 1e3:.0f}"])
    print_table(f"Queries ({next(iter(stubs))})",
                ["voice", "reference", "transcript", "errors", "ms"], rows)
    return list(results.values())


def report(results: list[Results]) -> None:
    base = results[0]
    rows = [[r.name, f"{r.wer:.1%}", f"{r.errors}/{r.words}", f"{median_ms(r.latency_s):.0f}",
             f"{statistics.median(r.inference_ms):.0f}",
             f"{median_ms(r.latency_s) / median_ms(base.latency_s):.2f}x"] for r in results]
    print_table(f"Transcribe, {len(base.latency_s)} queries each, interleaved",
                ["config", "WER", "errors/words", "median ms", "inference ms", "latency ratio"],
                rows)
    latency = median_ms(base.latency_s)
    print(f"\n{base.name}: WER {base.wer:.1%} (target <= {TARGET_WER:.0%}), median latency "
          f"{latency:.0f} ms per query (target <= {TARGET_LATENCY_MS:.0f} ms)")
