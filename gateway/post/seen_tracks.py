"""seen_tracks: {label: person, window_s: 60, into: people_last_minute} counts the unique
tracks seen in the last window_s seconds."""

from __future__ import annotations

from pydantic import Field

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.post.over_tracks import OverTracks
from oricf.gateway.tracking.measures import SeenInWindow
from oricf.gateway.values import Record


class SeenTracksStep(OverTracks):
    window_s: float = Field(60, gt=0, le=86400)
    into: str = "seen"


class SeenTracks(Step[SeenTracksStep]):
    def __init__(self, settings: SeenTracksStep) -> None:
        super().__init__(settings)
        self.reads, self.writes = frozenset({settings.tracks}), settings.into
        self.seen = SeenInWindow(settings.label, settings.window_s)

    def run(self, record: Record) -> None:
        record[self.settings.into] = self.seen.update(record[self.settings.tracks])


COMPONENT = StepKind("seen_tracks", SeenTracksStep, SeenTracks, rank=7)
