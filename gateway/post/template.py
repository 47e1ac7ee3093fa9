"""template: {text: "I see {count} people.", into: text} fills a text from record fields."""

from __future__ import annotations

from pydantic import field_validator

from oricf.config import Schema
from oricf.errors import InvalidInput
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Record, template_fields


class TemplateStep(Schema):
    text: str
    into: str = "text"

    @field_validator("text")
    @classmethod
    def _template(cls, value: str) -> str:
        template_fields(value)  # a malformed template (e.g. an unclosed brace) is refused
        return value


def build(step: TemplateStep) -> Step:
    def run(record: Record) -> None:
        try:
            record[step.into] = step.text.format_map(record)
        except (KeyError, IndexError, ValueError) as exc:
            raise InvalidInput(f"template {step.text!r}: cannot fill {exc}") from None

    return Step(frozenset(template_fields(step.text)), step.into, run)


COMPONENT = StepKind("template", TemplateStep, build, rank=4)
