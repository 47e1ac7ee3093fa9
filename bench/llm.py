"""`oricf bench llm`: how often the language model states the right people count, and how fast.

Starts the real service in-process on a free port for each model, asks varied count
questions with the count as a typed fact in the request (as the gateway sends it) over
GenerateStream, and grades each answer: it must state the right count and no other.
Also measures prompt-prefix reuse: the same questions with the KV cache of the fixed
prefix kept (the default) and thrown away before every call.

    oricf bench llm                                   # both catalog models
    oricf bench llm --model gemma3-270m --show        # one model, print every answer
    oricf bench llm --threads 1 --threads 2           # thread counts side by side
    oricf bench llm --gpu-layers 0 --gpu-layers -1    # the CPU against all layers on the GPU
    oricf bench llm --prompt my-prompt.yaml
    oricf bench llm --protocol grpc,openai            # gRPC against the OpenAI API (latency)
"""

from __future__ import annotations

import argparse
import math
import re
import statistics
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import grpc

from oricf.bench.protocols import parse_protocols
from oricf.config import shipped_service_config
from oricf.services.local import local_service, service_config
from oricf.stats import p90
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc

MODELS = ("gemma3-270m", "smollm2-135m-instruct")
PHRASINGS = (
    "How many people do you see?",
    "Is anyone there?",
    "Are you alone?",
    "How many humans are in the room?",
    "How many persons are in front of you?",
    "Is there somebody in the room?",
    "Do you see anyone?",
    "Count the people you can see.",
    "How many people are here right now?",
    "Is there a person in view?",
    "Are there any people around?",
    "How many visitors are there?",
    "Anybody here?",
    "How many people are in the room?",
    "Am I the only one here?",
    "Do you see any humans?",
    "What is the number of people in front of you?",
    "Is the room empty?",
    "How many folks can you spot?",
    "Is there a single person?",
)
MAX_COUNT = 15
NUMBER_WORDS = (
    "zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
    "eleven", "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen", "eighteen",
    "nineteen", "twenty")
ZERO_PHRASES = re.compile(r"\b(no one|no-one|nobody|no people|no persons|no humans|zero)\b")
SIDE_SAMPLE = 8        # questions with an unknown count; questions without prefix reuse
DEADLINE_S = 30.0


def questions(n: int) -> list[tuple[str, int]]:
    """n distinct (question, count) pairs, each count 0-15 asked in turn, phrasings rotating.

    Every 80 questions the phrasings shift by one, so up to 320 (all pairs) never repeat.
    The first 64 use every count 4 times and every phrasing 3 or 4 times.
    """
    counts = MAX_COUNT + 1
    block = math.lcm(counts, len(PHRASINGS))  # distinct pairs before the phrasings repeat
    pairs = []
    for i in range(min(n, counts * len(PHRASINGS))):
        shift = i // block
        pairs.append((PHRASINGS[(i + shift) % len(PHRASINGS)], i % counts))
    return pairs


def stated_counts(answer: str) -> set[int]:
    """The people counts an answer states, as digits, number words or "no one"-type phrases."""
    text = answer.lower()
    counts = {0} if ZERO_PHRASES.search(text) else set()
    text = ZERO_PHRASES.sub(" ", text)  # "no one" must not read as "one"
    counts |= {int(d) for d in re.findall(r"\b\d+\b", text)}
    counts |= {i for i, word in enumerate(NUMBER_WORDS) if re.search(rf"\b{word}\b", text)}
    return counts


def is_right(answer: str, count: int) -> bool:
    return stated_counts(answer) == {count}


@dataclass
class Answer:
    question: str
    count: int | None      # None: the count is unknown (absent, or too old in the facts)
    text: str
    first_s: float
    total_s: float

    @property
    def right(self) -> bool:
        if self.count is None:
            return not stated_counts(self.text)  # must not make a count up
        return is_right(self.text, self.count)


def people_count(count: int, age_s: float = 0.5) -> common_pb2.Fact:
    """The count as the gateway passes it: an integer with its age (a fresh one by default)."""
    return common_pb2.Fact(name="people_count", integer=count, age_s=age_s)


def ask(stub: language_pb2_grpc.LanguageModelStub, question: str, count: int | None,
        facts: list[common_pb2.Fact] | None = None) -> Answer:
    if facts is None:
        facts = [] if count is None else [people_count(count)]
    request = language_pb2.GenerateRequest(prompt=question, facts=facts)
    started = time.perf_counter()
    first = None
    pieces = []
    for message in stub.GenerateStream(request, timeout=DEADLINE_S):
        if first is None and message.text:
            first = time.perf_counter() - started
        pieces.append(message.text)
    total = time.perf_counter() - started
    return Answer(question, count, "".join(pieces), total if first is None else first, total)


def ask_unknown(stub: language_pb2_grpc.LanguageModelStub, n: int) -> list[Answer]:
    """Questions whose count is absent or too old: the answer must state no count."""
    facts: list[list[common_pb2.Fact]] = [[], [people_count(4, age_s=60.0)]]
    return [ask(stub, PHRASINGS[i % len(PHRASINGS)], None, facts[i % 2]) for i in range(n)]


@contextmanager
def service(overrides: dict[str, Any], config_path: Path) -> Iterator[grpc.Channel]:
    config = service_config("llm", overrides, config_path)
    with local_service("llm", config) as host, \
            grpc.insecure_channel(f"127.0.0.1:{host.port}") as channel:
        yield channel


@dataclass(frozen=True)
class Setup:
    model: str
    threads: int | None    # None: the YAML's
    gpu_layers: int | None = None  # None: the YAML's

    @property
    def label(self) -> str:
        layers = {None: "", 0: " cpu", -1: " gpu"}.get(self.gpu_layers, f" gpu{self.gpu_layers}")
        return self.model + ("" if self.threads is None else f" x{self.threads}") + layers


def overrides_for(setup: Setup, prompt: Path | None, reuse: bool) -> dict[str, Any]:
    settings: dict[str, Any] = {"name": setup.model, "reuse_prefix": reuse}
    if setup.threads is not None:
        settings["threads"] = setup.threads
    if setup.gpu_layers is not None:
        settings["gpu_layers"] = setup.gpu_layers
    data: dict[str, Any] = {"server": {"listen": "127.0.0.1:0"}, "model": settings}
    if prompt is not None:
        data["prompts"] = {setup.model: str(prompt.resolve())}
    return data


def run_setup(setup: Setup, args: argparse.Namespace) -> dict[str, Any]:
    asked = questions(args.questions)
    with service(overrides_for(setup, args.prompt, reuse=True), args.config) as channel:
        stub = language_pb2_grpc.LanguageModelStub(channel)
        ran_on = stub.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=10).providers[0]
        answers = [ask(stub, q, c) for q, c in asked]
        unknown = ask_unknown(stub, SIDE_SAMPLE)
    with service(overrides_for(setup, args.prompt, reuse=False), args.config) as channel:
        stub = language_pb2_grpc.LanguageModelStub(channel)
        cold = [ask(stub, q, c) for q, c in asked[:SIDE_SAMPLE]]
    if args.show:
        for a in answers + unknown:
            count = "?" if a.count is None else a.count
            print(f"  {'ok ' if a.right else 'BAD'} {count:>2} {a.question:46} -> {a.text}")
    return {
        "label": setup.label,
        "ran_on": ran_on,
        "right": sum(a.right for a in answers),
        "asked": len(answers),
        "unknown_right": sum(a.right for a in unknown),
        "first": statistics.median(a.first_s for a in answers),
        "total": statistics.median(a.total_s for a in answers),
        "p90": p90([a.total_s for a in answers]),
        "cold_first": statistics.median(a.first_s for a in cold),
    }


def print_table(rows: Sequence[dict[str, Any]]) -> None:
    print(f"\n{'model':28} {'ran on':7} {'right':>9} {'share':>6} {'unknown':>7} {'1st tok':>8} "
          f"{'answer':>8} {'p90':>7} {'1st tok, no prefix reuse':>25}")
    for r in rows:
        ratio = r["cold_first"] / r["first"] if r["first"] else float("nan")
        print(f"{r['label']:28} {r['ran_on']:7} {r['right']:>4}/{r['asked']:<4} "
              f"{r['right'] / r['asked']:6.0%} "
              f"{r['unknown_right']:>4}/{SIDE_SAMPLE:<2} "
              f"{r['first'] * 1e3:6.0f}ms {r['total'] * 1e3:6.0f}ms {r['p90'] * 1e3:5.0f}ms "
              f"{r['cold_first'] * 1e3:14.0f}ms ({ratio:.1f}x)")
    print("medians over the questions, measured by the client over gRPC (GenerateStream).\n"
          "right: the answer states the right count and no other; unknown: with the count "
          "absent or stale, the answer states none; xN: llama.cpp threads")


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="oricf bench llm", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", action="append", choices=MODELS,
                        help="catalog model to measure (repeatable; default: both)")
    parser.add_argument("--config", type=Path, default=shipped_service_config("llm"),
                        help="service YAML (default configs/services/llm.yaml)")
    parser.add_argument("--prompt", type=Path, help="prompt template for every model measured")
    parser.add_argument("--threads", type=int, action="append",
                        help="llama.cpp threads (repeatable, to compare; default: the YAML's)")
    parser.add_argument("--gpu-layers", type=int, action="append",
                        help="layers on the GPU, -1 all (repeatable, to compare; default: "
                             "the YAML's)")
    parser.add_argument("--questions", type=int, default=64, help="how many questions")
    parser.add_argument("--show", action="store_true", help="print every answer")
    parser.add_argument("--protocol", type=parse_protocols, metavar="grpc,openai",
                        help="instead: latency over these protocols side by side "
                             "(bench/protocols.py)")
    args = parser.parse_args(argv)
    if args.questions < SIDE_SAMPLE:
        parser.error(f"--questions must be at least {SIDE_SAMPLE}")
    return args


def main(argv: Sequence[str]) -> int:
    args = parse_args(argv)
    if args.protocol:
        from oricf.bench.llm_protocols import compare

        return compare(args, questions(args.questions))
    rows = []
    for model in args.model or MODELS:
        for threads in args.threads or [None]:
            for layers in args.gpu_layers or [None]:
                setup = Setup(model, threads, layers)
                print(f"{setup.label}: asking {args.questions} count questions...", flush=True)
                rows.append(run_setup(setup, args))
    print_table(rows)
    return 0
