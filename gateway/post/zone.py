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


def build(step: ZoneStep) -> Step:
    zone = Zone(step.polygon, step.label, step.anchor, step.window_s)

    def run(record: Record) -> None:
        record[step.into] = zone.update(record[step.tracks])[step.measure]

    return Step(frozenset({step.tracks}), step.into, run)


COMPONENT = StepKind("zone", ZoneStep, build, rank=8)
