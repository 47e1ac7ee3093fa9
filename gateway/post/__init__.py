"""Post steps: what a route does to its record after the call, in order, one module each.

    map_labels: {person: human}        rename detection labels
    filter: {labels: [..], min_score}  keep matching detections
    count: {label: person, into: count}
    annotate: {into: annotated}        draw the detections on the input image
    template: {text: "I see {count} people.", into: text}
    track: {labels: [person], min_hits: 2, max_age_s: 1}   follow objects: track ids, tracks
    count_tracks: {label: person, hold_s: 0.3, into: people_now}
    seen_tracks: {label: person, window_s: 60, into: people_last_minute}
    zone: {polygon: [[x, y], ...], measure: entries, into: door_entries}
    line: {start: [x, y], end: [x, y], measure: in, into: came_in}

Every step says which record fields it reads and which it writes, so a pipeline whose steps
or outputs name a field its route does not have is refused when it loads. Adding a step is
one module with a `build` (and its schema), its key in PostStep and its line in BUILDERS.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import model_validator

from oricf.config import Schema
from oricf.gateway.post import (
    annotate,
    count,
    count_tracks,
    line,
    map_labels,
    seen_tracks,
    template,
    track,
    zone,
)
from oricf.gateway.post import filter as filter_step
from oricf.gateway.post.annotate import AnnotateStep
from oricf.gateway.post.base import Run, Step
from oricf.gateway.post.count import CountStep
from oricf.gateway.post.count_tracks import CountTracksStep
from oricf.gateway.post.filter import FilterStep
from oricf.gateway.post.line import LineStep
from oricf.gateway.post.seen_tracks import SeenTracksStep
from oricf.gateway.post.template import TemplateStep
from oricf.gateway.post.track import TrackStep
from oricf.gateway.post.zone import ZoneStep
from oricf.gateway.values import Record

BUILDERS: dict[str, Callable[[Any], Step]] = {
    "map_labels": map_labels.build,
    "filter": filter_step.build,
    "count": count.build,
    "annotate": annotate.build,
    "template": template.build,
    "track": track.build,
    "count_tracks": count_tracks.build,
    "seen_tracks": seen_tracks.build,
    "zone": zone.build,
    "line": line.build,
}


class PostStep(Schema):
    """One post step: exactly one of the keys."""

    map_labels: dict[str, str] | None = None
    filter: FilterStep | None = None
    count: CountStep | None = None
    annotate: AnnotateStep | None = None
    template: TemplateStep | None = None
    track: TrackStep | None = None
    count_tracks: CountTracksStep | None = None
    seen_tracks: SeenTracksStep | None = None
    zone: ZoneStep | None = None
    line: LineStep | None = None

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
