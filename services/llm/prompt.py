"""The prompt template (configs/prompts/*.yaml) and its rendering.

A prompt is the template's fixed part (system text and few-shot examples) followed by the
request's part (its facts and question). The fixed part comes first on purpose: llama.cpp
keeps the KV cache of the longest common token prefix, so only the request's part is
evaluated on each call.

Facts come from the request's typed facts (oricf.v1.Fact). A fact the template names
renders with its `known` text; when the request does not give it, gives it without a value
or with a blank text, it renders as `unknown`; when the producer marks it stale, or its
age_s is over the template's `max_age_s`, it renders as `stale`, so the model can say it
does not know. A fact of unknown age is never too old. Values render as text: integers as
digits, numbers in up to 15 significant digits, flags as "yes" or "no".
"""

from __future__ import annotations

import math
import string
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pydantic import (
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    field_validator,
    model_validator,
)

from oricf.config import Schema
from oricf.services.llm.domain import Fact, FactValue


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
    name: str = Field(min_length=1, description="the fact's name, e.g. people_count")
    known: str = Field(description="{value}")
    unknown: str = Field(description="when the fact is absent or has no value")
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
    facts: dict[str, StrictStr | StrictInt | StrictFloat | StrictBool] = Field(
        default_factory=dict, description="name -> value, current and of unknown age")
    question: str = Field(min_length=1)
    answer: str = Field(min_length=1)

    @field_validator("facts", mode="before")
    @classmethod
    def _typed_values(cls, value: Any) -> Any:
        """One clear message instead of one per member of the value union."""
        for name, item in (value.items() if isinstance(value, dict) else ()):
            if not isinstance(item, (str, int, float, bool)) or (
                    isinstance(item, float) and not math.isfinite(item)):
                raise ValueError(f"{name}: {item!r} is not a text, an integer, a finite "
                                 f"number or a flag")
        return value


class PromptTemplate(Schema):
    format: PromptFormat
    system: str = ""
    facts: list[FactTemplate] = Field(default_factory=list)
    fact_separator: str = "; "
    no_facts: str = Field("none", description="{facts} when nothing at all is known")
    other_facts: str | None = Field(
        None, description="'{name}: {value}' renders facts the template does not name (a "
                          "stale one or one without a value as 'unknown'); unset: ignored")
    examples: list[Example] = Field(default_factory=list)
    collapse_whitespace: bool = Field(
        True, description="questions become one line (a newline would end the turn early)")

    @field_validator("other_facts")
    @classmethod
    def _other_placeholders(cls, value: str | None) -> str | None:
        return None if value is None else _check_fields(value, ["name", "value"])

    @field_validator("facts")
    @classmethod
    def _unique_names(cls, value: list[FactTemplate]) -> list[FactTemplate]:
        names = [f.name for f in value]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"fact name(s) listed twice: {', '.join(duplicates)}")
        return value


@dataclass(frozen=True)
class RenderedPrompt:
    text: str
    prefix: str        # the fixed part, identical for every request
    facts: str         # what the request's facts rendered to (for logs)


class PromptRenderer:
    """Renders requests with one template; the fixed prefix is rendered once."""

    def __init__(self, template: PromptTemplate) -> None:
        self.template = template
        self._named = {f.name for f in template.facts}
        self.prefix = self._prefix(template.system)

    def _prefix(self, system: str) -> str:
        fmt = self.template.format
        parts = [fmt.header.format(system=system)]
        for example in self.template.examples:
            facts = [Fact(name, value) for name, value in example.facts.items()]
            parts.append(self._turn(example.question, facts))
            parts.append(fmt.answer.format(answer=example.answer))
        return "".join(parts)

    @property
    def stop(self) -> list[str]:
        return list(self.template.format.stop)

    def render(self, question: str, facts: Sequence[Fact], system: str = "",
               history: Sequence[tuple[str, str]] = ()) -> RenderedPrompt:
        """The prompt for a question. A conversation's own system text follows the
        template's; its earlier (question, answer) turns follow the examples, each with
        this request's facts (the facts are what is known now)."""
        rendered = self.render_facts(facts)
        prefix = self._prefix(f"{self.template.system} {system}") if system else self.prefix
        answer = self.template.format.answer
        earlier = "".join(self._turn(q, facts) + answer.format(answer=self._question(a))
                          for q, a in history)
        turn = self.template.format.turn.format(facts=rendered, question=self._question(question))
        return RenderedPrompt(prefix + earlier + turn, prefix, rendered)

    def render_facts(self, facts: Sequence[Fact]) -> str:
        by_name: Mapping[str, Fact] = {fact.name: fact for fact in facts}
        lines = [_render_fact(template, by_name.get(template.name))
                 for template in self.template.facts]
        if self.template.other_facts is not None:
            lines += [self.template.other_facts.format(name=fact.name, value=_other_value(fact))
                      for fact in sorted(facts, key=lambda f: f.name)
                      if fact.name not in self._named]
        return self.template.fact_separator.join(lines) or self.template.no_facts

    def _turn(self, question: str, facts: Sequence[Fact]) -> str:
        return self.template.format.turn.format(facts=self.render_facts(facts),
                                                question=self._question(question))

    def _question(self, question: str) -> str:
        return " ".join(question.split()) if self.template.collapse_whitespace else question


def value_text(value: FactValue | None) -> str:
    """A value as the prompt shows it; "" when there is nothing to state."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.15g}"
    return str(value).strip()


def _is_out_of_date(template: FactTemplate, fact: Fact) -> bool:
    too_old = (fact.age_s is not None and template.max_age_s is not None
               and fact.age_s > template.max_age_s)
    return fact.stale or too_old


def _render_fact(template: FactTemplate, fact: Fact | None) -> str:
    value = "" if fact is None else value_text(fact.value)
    if fact is None or not value:
        return template.unknown
    if _is_out_of_date(template, fact):
        if template.stale is None:
            return template.unknown
        age = "?" if fact.age_s is None else f"{fact.age_s:.0f}"
        return template.stale.format(value=value, age_s=age)
    return template.known.format(value=value)


def _other_value(fact: Fact) -> str:
    """A fact the template does not name has no age limit; only the producer's flag counts."""
    if fact.stale:
        return "unknown"
    return value_text(fact.value) or "unknown"
