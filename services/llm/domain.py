"""The language model's domain values: what a generation is asked and what it returns."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

# Raises Cancelled or DeadlineExceeded when the caller no longer wants the answer. Called
# between tokens and while waiting for the model, so the model never needs to know gRPC.
StillWanted = Callable[[], None]


@dataclass(frozen=True)
class GenerationRequest:
    prompt: str
    context: Mapping[str, str] = field(default_factory=dict)
    max_tokens: int = 48
    temperature: float = 0.0
    stop: tuple[str, ...] = ()


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
