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


def build(step: SeenTracksStep) -> Step:
    seen = SeenInWindow(step.label, step.window_s)

    def run(record: Record) -> None:
        record[step.into] = seen.update(record[step.tracks])

    return Step(frozenset({step.tracks}), step.into, run)


COMPONENT = StepKind("seen_tracks", SeenTracksStep, build, rank=7)
