"""count_tracks: {label: person, hold_s: 0.3, into: people_now} counts confirmed tracks seen
within the last hold_s seconds: a count that holds still through a missed detection."""

from __future__ import annotations

from pydantic import Field

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.post.over_tracks import OverTracks
from oricf.gateway.tracking.measures import count_now
from oricf.gateway.values import Record


class CountTracksStep(OverTracks):
    hold_s: float = Field(0.3, ge=0, le=3600)
    into: str = "count"


def build(step: CountTracksStep) -> Step:
    def run(record: Record) -> None:
        record[step.into] = count_now(record[step.tracks], step.label, step.hold_s)

    return Step(frozenset({step.tracks}), step.into, run)


COMPONENT = StepKind("count_tracks", CountTracksStep, build, rank=6)
