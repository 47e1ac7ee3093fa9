"""The prompt template (configs/prompts/*.yaml) and its rendering.

A prompt is the template's fixed part (system text and few-shot examples) followed by the
request's part (its facts and question). The fixed part comes first on purpose: llama.cpp
keeps the KV cache of the longest common token prefix, so only the request's part is
evaluated on each call.

Facts come from the request's context map. A fact the template names renders with its
`known` text; when the key is absent, empty or "unknown" it renders as `unknown`; when the
caller marks it stale (`<key>_stale: "true"`) or says it is older than `max_age_s`
(`<key>_age_s: "12.5"`) it renders as `stale`, so the model can say it does not know.
"""

from __future__ import annotations

import math
import string
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.context import AGE_SUFFIX, STALE_SUFFIX
from oricf.errors import InvalidInput

UNKNOWN_VALUES = frozenset({"", "unknown", "none", "null", "n/a"})
TRUE_VALUES = frozenset({"1", "true", "yes"})


def _check_fields(template: str, allowed: Iterable[str]) -> str:
    """Refuses a format string with placeholders other than `allowed` (or broken braces)."""
    allowed = set(allowed)
    try:
        names = {name for _, name, _, _ in string.Formatter().parse(template) if name is not None}
    except ValueError as exc:
        raise ValueError(f"bad format string {template!r}: {exc}") from None
    unknown = sorted(names - allowed)
    if unknown:
        raise ValueError(f"unknown placeholder(s) {{{'}, {'.join(unknown)}}} in {template!r}; "
                         f"allowed: {', '.join('{' + a + '}' for a in sorted(allowed))}")
    return template


class PromptFormat(Schema):
    """The model's own format: a chat template or a plain completion layout."""

    header: str = Field("{system}", description="once at the start; {system}")
    turn: str = Field(description="per example and for the request; {facts}, {question}")
    answer: str = Field(description="after an example's turn; {answer}")
    stop: list[str] = Field(default_factory=list, description="stop sequences of this format")

    @model_validator(mode="after")
    def _placeholders(self) -> PromptFormat:
        _check_fields(self.header, ["system"])
        _check_fields(self.turn, ["facts", "question"])
        _check_fields(self.answer, ["answer"])
        if any(not s for s in self.stop):
            raise ValueError("stop: empty stop sequence")
        return self


class FactTemplate(Schema):
    key: str = Field(min_length=1, description="context key, e.g. people_count")
    known: str = Field(description="{value}")
    unknown: str = Field(description="when the key is absent or empty")
    stale: str | None = Field(None, description="{value}, {age_s}; unset: the unknown text")
    max_age_s: float | None = Field(None, gt=0, description="older values count as stale")

    @model_validator(mode="after")
    def _placeholders(self) -> FactTemplate:
        _check_fields(self.known, ["value"])
        _check_fields(self.unknown, [])
        if self.stale is not None:
            _check_fields(self.stale, ["value", "age_s"])
        return self


class Example(Schema):
    context: dict[str, str] = Field(default_factory=dict)
    question: str = Field(min_length=1)
    answer: str = Field(min_length=1)


class PromptTemplate(Schema):
    format: PromptFormat
    system: str = ""
    facts: list[FactTemplate] = Field(default_factory=list)
    fact_separator: str = "; "
    no_facts: str = Field("none", description="{facts} when nothing at all is known")
    other_facts: str | None = Field(
        None, description="'{key}: {value}' renders context keys the template does not name; "
                          "unset: they are ignored")
    examples: list[Example] = Field(default_factory=list)
    collapse_whitespace: bool = Field(
        True, description="questions become one line (a newline would end the turn early)")

    @field_validator("other_facts")
    @classmethod
    def _other_placeholders(cls, value: str | None) -> str | None:
        return None if value is None else _check_fields(value, ["key", "value"])

    @field_validator("facts")
    @classmethod
    def _unique_keys(cls, value: list[FactTemplate]) -> list[FactTemplate]:
        keys = [f.key for f in value]
        duplicates = sorted({k for k in keys if keys.count(k) > 1})
        if duplicates:
            raise ValueError(f"fact key(s) listed twice: {', '.join(duplicates)}")
        return value


@dataclass(frozen=True)
class RenderedPrompt:
    text: str
    prefix: str        # the fixed part, identical for every request
    facts: str         # what the request's context rendered to (for logs)


class PromptRenderer:
    """Renders requests with one template; the fixed prefix is rendered once."""

    def __init__(self, template: PromptTemplate) -> None:
        self.template = template
        self._named = {f.key for f in template.facts}
        fmt = template.format
        parts = [fmt.header.format(system=template.system)]
        for example in template.examples:
            parts.append(self._turn(example.question, example.context))
            parts.append(fmt.answer.format(answer=example.answer))
        self.prefix = "".join(parts)

    @property
    def stop(self) -> list[str]:
        return list(self.template.format.stop)

    def render(self, question: str, context: Mapping[str, str]) -> RenderedPrompt:
        facts = self.render_facts(context)
        turn = self.template.format.turn.format(facts=facts, question=self._question(question))
        return RenderedPrompt(self.prefix + turn, self.prefix, facts)

    def render_facts(self, context: Mapping[str, str]) -> str:
        lines = [_render_fact(fact, context) for fact in self.template.facts]
        if self.template.other_facts is not None:
            lines += [self.template.other_facts.format(key=key, value=value)
                      for key, value in sorted(context.items()) if self._is_other(key)]
        return self.template.fact_separator.join(lines) or self.template.no_facts

    def _turn(self, question: str, context: Mapping[str, str]) -> str:
        return self.template.format.turn.format(facts=self.render_facts(context),
                                                question=self._question(question))

    def _question(self, question: str) -> str:
        return " ".join(question.split()) if self.template.collapse_whitespace else question

    def _is_other(self, key: str) -> bool:
        base = key.removesuffix(AGE_SUFFIX).removesuffix(STALE_SUFFIX)
        return key not in self._named and base not in self._named


def _render_fact(fact: FactTemplate, context: Mapping[str, str]) -> str:
    value = context.get(fact.key, "").strip()
    if value.lower() in UNKNOWN_VALUES:
        return fact.unknown
    age = _age(context, fact.key)
    stale_flag = context.get(fact.key + STALE_SUFFIX, "").strip().lower() in TRUE_VALUES
    too_old = age is not None and fact.max_age_s is not None and age > fact.max_age_s
    if stale_flag or too_old:
        if fact.stale is None:
            return fact.unknown
        return fact.stale.format(value=value, age_s=f"{age:.0f}" if age is not None else "?")
    return fact.known.format(value=value)


def _age(context: Mapping[str, str], key: str) -> float | None:
    text = context.get(key + AGE_SUFFIX)
    if text is None or not text.strip():
        return None
    try:
        age = float(text)
    except ValueError:
        raise InvalidInput(f"context '{key}{AGE_SUFFIX}' must be a number of seconds, "
                           f"got {text!r}") from None
    if not math.isfinite(age) or age < 0:
        raise InvalidInput(f"context '{key}{AGE_SUFFIX}' must be >= 0 seconds, got {text!r}")
    return age
