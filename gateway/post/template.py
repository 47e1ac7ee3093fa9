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


class Template(Step[TemplateStep]):
    def __init__(self, settings: TemplateStep) -> None:
        super().__init__(settings)
        self.reads, self.writes = frozenset(template_fields(settings.text)), settings.into

    def run(self, record: Record) -> None:
        step = self.settings
        try:
            record[step.into] = step.text.format_map(record)
        except (KeyError, IndexError, ValueError) as exc:
            raise InvalidInput(f"template {step.text!r}: cannot fill {exc}") from None


COMPONENT = StepKind("template", TemplateStep, Template, rank=4)
