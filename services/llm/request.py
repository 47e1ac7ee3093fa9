"""GenerateRequest -> GenerationRequest, refusing what the model should never see."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from oricf.errors import InvalidInput
from oricf.services.llm.config import GenerationSettings, InputLimits
from oricf.services.llm.domain import Fact, FactValue, GenerationRequest
from oricf.v1 import common_pb2, language_pb2

FACT_NAME = re.compile(r"^[A-Za-z0-9_.\-]+$")
MAX_TEMPERATURE = 2.0


def to_generation_request(request: language_pb2.GenerateRequest, generation: GenerationSettings,
                          limits: InputLimits) -> GenerationRequest:
    prompt = _prompt(request.prompt, limits)
    facts = _facts(request.facts, limits)
    return GenerationRequest(
        prompt=prompt,
        facts=facts,
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


def _facts(facts: Sequence[common_pb2.Fact], limits: InputLimits) -> tuple[Fact, ...]:
    if len(facts) > limits.max_facts:
        raise InvalidInput(f"{len(facts)} facts; the limit is {limits.max_facts}")
    checked: dict[str, int] = {}
    for i, fact in enumerate(facts):
        _check_name(fact.name, i, limits)
        if fact.name in checked:
            raise InvalidInput(f"fact '{fact.name}' is given twice (facts[{checked[fact.name]}] "
                               f"and facts[{i}]); send each fact once")
        checked[fact.name] = i
    return tuple(Fact(f.name, _value(f, limits), _age(f), f.stale) for f in facts)


def _check_name(name: str, index: int, limits: InputLimits) -> None:
    if not name:
        raise InvalidInput(f"facts[{index}]: name is empty; name each fact, e.g. 'people_count'")
    if len(name) > limits.max_name_chars or not FACT_NAME.match(name):
        raise InvalidInput(f"facts[{index}]: name {name[:80]!r} is not a name of at most "
                           f"{limits.max_name_chars} letters, digits, '_', '.' or '-'")


def _value(fact: common_pb2.Fact, limits: InputLimits) -> FactValue | None:
    kind = fact.WhichOneof("value")
    if kind is None:
        return None
    value: FactValue = getattr(fact, kind)
    if kind == "text" and len(fact.text) > limits.max_text_chars:
        raise InvalidInput(f"fact '{fact.name}': text has {len(fact.text)} characters; the "
                           f"limit is {limits.max_text_chars}")
    if kind == "number" and not math.isfinite(fact.number):
        raise InvalidInput(f"fact '{fact.name}': number must be finite, got {fact.number}")
    return value


def _age(fact: common_pb2.Fact) -> float | None:
    if not fact.HasField("age_s"):
        return None
    if not math.isfinite(fact.age_s) or fact.age_s < 0:
        raise InvalidInput(f"fact '{fact.name}': age_s must be a finite number of seconds "
                           f">= 0, got {fact.age_s} (leave it unset when the age is not known)")
    return fact.age_s


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
