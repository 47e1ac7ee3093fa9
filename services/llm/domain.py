"""The language model's domain values: what a generation is asked and what it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeAlias

# Raises Cancelled or DeadlineExceeded when the caller no longer wants the answer. Called
# between tokens and while waiting for the model, so the model never needs to know gRPC.
StillWanted = Callable[[], None]


FactValue: TypeAlias = str | int | float | bool


@dataclass(frozen=True)
class Fact:
    """A fact from another model (oricf.v1.Fact), checked: a unique name, a finite value."""

    name: str
    value: FactValue | None = None   # None: the producer has no value
    age_s: float | None = None       # None: the age is not known
    stale: bool = False              # the producer says it is out of date


@dataclass(frozen=True)
class JsonOutput:
    """Answer in JSON, enforced by a grammar while decoding: any JSON object, or one that
    validates against a JSON Schema (the checked GBNF grammar made from it)."""

    grammar: str | None = None


@dataclass(frozen=True)
class GenerationRequest:
    prompt: str
    facts: tuple[Fact, ...] = ()
    max_tokens: int = 48
    temperature: float = 0.0
    stop: tuple[str, ...] = ()
    # A conversation (the OpenAI API): the caller's system text, added to the template's,
    # and earlier (question, answer) turns, rendered after the template's examples.
    system: str = ""
    history: tuple[tuple[str, str], ...] = ()
    json: JsonOutput | None = None
    seed: int | None = None
    top_p: float | None = None        # None: the service's


@dataclass(frozen=True)
class Finished:
    """The end of a generation: why it stopped, counts and timings (milliseconds)."""

    finish_reason: str          # "stop" or "length"
    prompt_tokens: int
    completion_tokens: int
    cached_tokens: int          # prompt tokens reused from the previous call's KV cache
    queue_ms: float
    preprocess_ms: float
    first_token_ms: float       # from the call to the first token, waiting included
    inference_ms: float
    total_ms: float


@dataclass(frozen=True)
class Chunk:
    """New text; the last chunk of a generation carries `finished` (its text may be empty)."""

    text: str
    finished: Finished | None = None


@dataclass
class GenerationStats:
    """Running totals of one model instance (logs, tests, introspection)."""

    generations: int = 0
    completion_tokens: int = 0
    stopped_early: int = 0              # cancelled or past the deadline
    last_finish_reason: str = ""        # "stop", "length", or the error that cut it short
    last_completion_tokens: int = 0
    last_cached_tokens: int = 0
    last_prompt_tokens: int = 0
