"""`oricf bench llm --protocol grpc,openai`: answer latency and time to first token of the
language service over gRPC (GenerateStream, Generate) and over its OpenAI-compatible API
(chat completions, streamed and not), interleaved question by question (protocols.py)."""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from oricf.bench.protocols import Endpoints, both_protocols, clock, interleave, report
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc

MEASURES = ("first token", "streamed answer", "answer")
DEADLINE_S = 30.0
Question = tuple[str, int]   # (question, the people count passed as a typed fact)


def _grpc(endpoints: Endpoints) -> Any:
    stub = language_pb2_grpc.LanguageModelStub(endpoints.grpc)

    def ask(question: Question) -> dict[str, float]:
        count = common_pb2.Fact(name="people_count", integer=question[1], age_s=0.5)
        request = language_pb2.GenerateRequest(prompt=question[0], facts=[count])
        started = clock()
        first = None
        for message in stub.GenerateStream(request, timeout=DEADLINE_S):
            if first is None and message.text:
                first = clock() - started
        streamed = clock() - started
        started = clock()
        stub.Generate(request, timeout=DEADLINE_S)
        return {"first token": first or streamed, "streamed answer": streamed,
                "answer": clock() - started}

    return ask


def _openai(endpoints: Endpoints, model: str) -> Any:
    api = endpoints.openai

    def ask(question: Question) -> dict[str, float]:
        options = {"model": model, "messages": [{"role": "user", "content": question[0]}],
                   "extra_body": {"facts": [{"name": "people_count", "integer": question[1],
                                             "age_s": 0.5}]}}
        started = clock()
        first = None
        for chunk in api.chat.completions.create(stream=True, **options):
            if first is None and chunk.choices and chunk.choices[0].delta.content:
                first = clock() - started
        streamed = clock() - started
        started = clock()
        api.chat.completions.create(**options)
        return {"first token": first or streamed, "streamed answer": streamed,
                "answer": clock() - started}

    return ask


def compare(args: argparse.Namespace, asked: list[Question]) -> int:
    """asked: the questions of `oricf bench llm` (it passes them: no import back)."""
    for model in args.model or ["gemma3-270m"]:
        print(f"{model}: {len(asked)} questions over {', '.join(args.protocol)}...",
              flush=True)
        overrides = ["--config", str(args.config)]
        with both_protocols("llm", *overrides, *_model_args(model, args)) as endpoints:
            asks = {"grpc": _grpc(endpoints), "openai": _openai(endpoints, model)}
            results = interleave(asked, {name: asks[name] for name in args.protocol},
                                 reset=_other_prompt(endpoints))
        report(f"{model}, oricf serve llm", results, MEASURES)
    return 0


def _other_prompt(endpoints: Endpoints) -> Callable[[], None]:
    """One token for an unrelated prompt: the model's prompt cache then holds only the
    template's shared prefix, as for any new question, whichever protocol asked last."""
    stub = language_pb2_grpc.LanguageModelStub(endpoints.grpc)
    request = language_pb2.GenerateRequest(prompt="Say hello.", max_tokens=1)

    def reset() -> None:
        stub.Generate(request, timeout=DEADLINE_S)

    return reset


def _model_args(model: str, args: argparse.Namespace) -> list[str]:
    """The model is chosen through an overlay, so the YAML given stays as it is."""
    folder = Path(tempfile.mkdtemp(prefix="oricf-bench-"))
    path = folder / "model.yaml"
    path.write_text(yaml.safe_dump({"model": {"name": model}}))
    return ["--overlay", str(path)]
