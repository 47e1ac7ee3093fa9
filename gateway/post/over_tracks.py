"""What the steps that measure over tracks share: the field they read (a `track` step's
output), the label they count, and where a track is (its box's anchor point)."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.tracking.geometry import Anchor


class OverTracks(Schema):
    tracks: str = Field("tracks", description="the field a track step wrote")
    label: str | None = Field(None, description="only tracks of this label (default: all)")
    into: str


class Placed(OverTracks):
    anchor: Anchor = Field("bottom", description="a track's place: its box's bottom centre "
                                                 "(where a person stands) or centre")
    window_s: float | None = Field(None, gt=0, le=86400,
                                   description="count events of the last window_s seconds "
                                               "(default: since the route started)")
