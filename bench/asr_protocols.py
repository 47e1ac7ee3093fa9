"""`oricf bench asr --protocol grpc,openai`: latency of the speech service over gRPC
(Transcribe, raw pcm_s16le) and over its OpenAI-compatible API (a WAV file uploaded as
multipart), interleaved query by query (protocols.py); the word error rate of each."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numpy as np

from oricf.audio import MODEL_RATE, encode_wav
from oricf.bench.protocols import Endpoints, both_protocols, clock, interleave, report
from oricf.v1 import speech_pb2, speech_pb2_grpc

MEASURES = ("transcript",)


Query = Any          # oricf.bench.asr.Query: text, voice, pcm (16 kHz pcm_s16le)
Score = Callable[[Query, str], int]   # word errors of a transcript of the query


def _grpc(endpoints: Endpoints, errors: dict[str, int], score: Score) -> Any:
    stub = speech_pb2_grpc.SpeechRecognizerStub(endpoints.grpc)

    def ask(query: Query) -> dict[str, float]:
        request = speech_pb2.TranscribeRequest(audio=speech_pb2.Audio(
            data=query.pcm, encoding="pcm_s16le", sample_rate=MODEL_RATE))
        started = clock()
        text = stub.Transcribe(request, timeout=30).text
        seconds = clock() - started
        errors["grpc"] += score(query, text)
        return {"transcript": seconds}

    return ask


def _openai(endpoints: Endpoints, errors: dict[str, int], score: Score) -> Any:
    api = endpoints.openai

    def ask(query: Query) -> dict[str, float]:
        wav = encode_wav(np.frombuffer(query.pcm, dtype="<i2"), MODEL_RATE)
        started = clock()
        text = api.audio.transcriptions.create(model="whisper-tiny-en",
                                               file=("query.wav", wav)).text
        seconds = clock() - started
        errors["openai"] += score(query, text)
        return {"transcript": seconds}

    return ask


def compare(args: argparse.Namespace, queries: list[Query], score: Score,
            words: Callable[[Query], int]) -> int:
    """The queries and their scoring come from `oricf bench asr` (no import back)."""
    errors = {"grpc": 0, "openai": 0}
    print(f"{len(queries)} queries over {', '.join(args.protocol)}...", flush=True)
    with both_protocols("asr") as endpoints:
        asks = {"grpc": _grpc(endpoints, errors, score),
                "openai": _openai(endpoints, errors, score)}
        results = interleave(queries, {name: asks[name] for name in args.protocol},
                             args.rounds)
    report("oricf serve asr", results, MEASURES)
    # every query of every round, and the first once more as the warm-up
    total = sum(words(q) for q in queries) * args.rounds + words(queries[0])
    for name in args.protocol:
        print(f"{name}: WER {errors[name] / total:.1%} over the same queries")
    return 0
