"""GenerateRequest -> GenerationRequest, refusing what the model should never see."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

from oricf.errors import InvalidInput
from oricf.services.llm.config import GenerationSettings, InputLimits
from oricf.services.llm.domain import GenerationRequest
from oricf.v1 import language_pb2

CONTEXT_KEY = re.compile(r"^[A-Za-z0-9_.\-]+$")
MAX_TEMPERATURE = 2.0


def to_generation_request(request: language_pb2.GenerateRequest, generation: GenerationSettings,
                          limits: InputLimits) -> GenerationRequest:
    prompt = _prompt(request.prompt, limits)
    context = _context(request.context, limits)
    return GenerationRequest(
        prompt=prompt,
        context=context,
        max_tokens=_max_tokens(request.max_tokens, generation),
        temperature=_temperature(request, generation),
        stop=_stops(request.stop, limits),
    )


def _prompt(prompt: str, limits: InputLimits) -> str:
    if not prompt.strip():
        raise InvalidInput("prompt is empty: send the question to answer")
    if len(prompt) > limits.max_prompt_chars:
        raise InvalidInput(f"prompt has {len(prompt)} characters; the limit is "
                           f"{limits.max_prompt_chars}")
    return prompt


def _context(context: Mapping[str, str], limits: InputLimits) -> dict[str, str]:
    if len(context) > limits.max_context_keys:
        raise InvalidInput(f"context has {len(context)} keys; the limit is "
                           f"{limits.max_context_keys}")
    for key, value in context.items():
        if len(key) > limits.max_key_chars or not CONTEXT_KEY.match(key):
            raise InvalidInput(f"context key {key[:80]!r} is not a name of at most "
                               f"{limits.max_key_chars} letters, digits, '_', '.' or '-'")
        if len(value) > limits.max_value_chars:
            raise InvalidInput(f"context '{key}' has {len(value)} characters; the limit is "
                               f"{limits.max_value_chars}")
    return dict(context)


def _max_tokens(requested: int, generation: GenerationSettings) -> int:
    if requested == 0:
        return generation.max_tokens
    if requested > generation.max_tokens_limit:
        raise InvalidInput(f"max_tokens {requested} is over this service's limit of "
                           f"{generation.max_tokens_limit} (0 for the default, "
                           f"{generation.max_tokens})")
    return requested


def _temperature(request: language_pb2.GenerateRequest, generation: GenerationSettings) -> float:
    if not request.HasField("temperature"):
        return generation.temperature
    value = request.temperature
    if math.isnan(value) or not 0 <= value <= MAX_TEMPERATURE:
        raise InvalidInput(f"temperature {value} is out of range [0, {MAX_TEMPERATURE}] "
                           f"(leave it unset for the default, {generation.temperature})")
    return float(value)


def _stops(stops: Sequence[str], limits: InputLimits) -> tuple[str, ...]:
    if len(stops) > limits.max_stop_sequences:
        raise InvalidInput(f"{len(stops)} stop sequences; the limit is "
                           f"{limits.max_stop_sequences}")
    for stop in stops:
        if not stop or len(stop) > limits.max_stop_chars:
            raise InvalidInput(f"stop sequence {stop[:40]!r} must have 1 to "
                               f"{limits.max_stop_chars} characters")
    return tuple(stops)
