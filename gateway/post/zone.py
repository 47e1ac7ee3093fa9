"""zone: {polygon: [[x, y], ...], measure: entries, into: door_entries} measures tracks in a
polygon of image pixels: `inside` now, `entries` and `exits` (since the route started, or
in the last window_s), `dwell_s` (the longest time a track now inside has been inside).
A track first seen inside has entered; one dropped while inside has left."""

from __future__ import annotations

from typing import Any

from pydantic import Field, field_validator

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.post.over_tracks import Placed
from oricf.gateway.tracking.bytetrack import MAX_COORDINATE, in_range
from oricf.gateway.tracking.measures import Zone, ZoneMeasure
from oricf.gateway.values import Record


def finite_point(point: tuple[float, float]) -> tuple[float, float]:
    if not in_range(point):
        raise ValueError(f"point {list(point)} is not two finite numbers of pixels "
                         f"(at most {MAX_COORDINATE:g})")
    return point


class ZoneStep(Placed):
    polygon: list[tuple[float, float]] = Field(min_length=3, max_length=256)
    measure: ZoneMeasure

    @field_validator("polygon")
    @classmethod
    def _finite(cls, value: list[Any]) -> list[Any]:
        return [finite_point(p) for p in value]


class ZoneMeasures(Step[ZoneStep]):
    def __init__(self, settings: ZoneStep) -> None:
        super().__init__(settings)
        self.reads, self.writes = frozenset({settings.tracks}), settings.into
        self.zone = Zone(settings.polygon, settings.label, settings.anchor, settings.window_s)

    def run(self, record: Record) -> None:
        step = self.settings
        record[step.into] = self.zone.update(record[step.tracks])[step.measure]


COMPONENT = StepKind("zone", ZoneStep, ZoneMeasures, rank=8)
