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


class CountTracks(Step[CountTracksStep]):
    def __init__(self, settings: CountTracksStep) -> None:
        super().__init__(settings)
        self.reads, self.writes = frozenset({settings.tracks}), settings.into

    def run(self, record: Record) -> None:
        step = self.settings
        record[step.into] = count_now(record[step.tracks], step.label, step.hold_s)


COMPONENT = StepKind("count_tracks", CountTracksStep, CountTracks, rank=6)
