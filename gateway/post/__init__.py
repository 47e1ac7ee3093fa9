"""Post steps: what a route does to its record after the call, in order, one module each.

    map_labels: {person: human}        rename detection labels
    filter: {labels: [..], min_score}  keep matching detections
    count: {label: person, into: count}
    annotate: {into: annotated}        draw the detections on the input image
    template: {text: "I see {count} people.", into: text}

Every step says which record fields it reads and which it writes, so a pipeline whose steps
or outputs name a field its route does not have is refused when it loads. Adding a step is
one module with a `build` (and its schema), its key in PostStep and its line in BUILDERS.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import model_validator

from oricf.config import Schema
from oricf.gateway.post import annotate, count, map_labels, template
from oricf.gateway.post import filter as filter_step
from oricf.gateway.post.annotate import AnnotateStep
from oricf.gateway.post.base import Run, Step
from oricf.gateway.post.count import CountStep
from oricf.gateway.post.filter import FilterStep
from oricf.gateway.post.template import TemplateStep
from oricf.gateway.values import Record

BUILDERS: dict[str, Callable[[Any], Step]] = {
    "map_labels": map_labels.build,
    "filter": filter_step.build,
    "count": count.build,
    "annotate": annotate.build,
    "template": template.build,
}


class PostStep(Schema):
    """One post step: exactly one of the keys."""

    map_labels: dict[str, str] | None = None
    filter: FilterStep | None = None
    count: CountStep | None = None
    annotate: AnnotateStep | None = None
    template: TemplateStep | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> PostStep:
        if len(self.model_fields_set) != 1:
            raise ValueError(f"give exactly one of {', '.join(BUILDERS)}")
        return self

    @property
    def kind(self) -> str:
        return next(iter(self.model_fields_set))

    def build(self) -> Step:
        return BUILDERS[self.kind](getattr(self, self.kind))


def chain(steps: list[PostStep]) -> Run:
    """All steps in order, as one."""
    runs = [step.build().run for step in steps]

    def run(record: Record) -> None:
        for step in runs:
            step(record)

    return run


__all__ = ["BUILDERS", "PostStep", "Step", "chain"]
