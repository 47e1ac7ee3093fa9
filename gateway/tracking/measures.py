"""Numbers over tracks as time goes on. Each measure sees every frame's confirmed tracks
(`Tracks`) and returns its value now; a track's place is its box's anchor point."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from oricf.gateway.tracking.bytetrack import TrackView
from oricf.gateway.tracking.geometry import (
    Anchor,
    Point,
    Polygon,
    anchor_point,
    segments_cross,
    side,
)


@dataclass(frozen=True)
class Tracks:
    """The confirmed tracks after one frame, and the frame's time (seconds)."""

    time: float
    tracks: list[TrackView]

    def of(self, label: str | None) -> list[TrackView]:
        return [t for t in self.tracks if label is None or t.label == label]

    def seen_now(self, label: str | None) -> list[TrackView]:
        return [t for t in self.of(label) if t.last_seen == self.time]


def count_now(tracks: Tracks, label: str | None, hold_s: float) -> int:
    """Confirmed tracks seen within the last hold_s: a person missed for a frame or two is
    still counted, so the count holds still."""
    return sum(1 for t in tracks.of(label) if tracks.time - t.last_seen <= hold_s)


class SeenInWindow:
    """Unique tracks seen in the last window_s seconds."""

    def __init__(self, label: str | None, window_s: float) -> None:
        self._label, self._window = label, window_s
        self._last_seen: dict[int, float] = {}

    def update(self, tracks: Tracks) -> int:
        for t in tracks.seen_now(self._label):
            self._last_seen[t.track_id] = t.last_seen
        cutoff = tracks.time - self._window
        self._last_seen = {i: s for i, s in self._last_seen.items() if s >= cutoff}
        return len(self._last_seen)


@dataclass
class _Events:
    """Event times, all of them or those of the last window_s seconds."""

    window_s: float | None
    times: deque[float] = field(default_factory=deque)
    total: int = 0

    def add(self, time: float) -> None:
        self.total += 1
        if self.window_s is not None:
            self.times.append(time)

    def count(self, now: float) -> int:
        if self.window_s is None:
            return self.total
        while self.times and self.times[0] < now - self.window_s:
            self.times.popleft()
        return len(self.times)


ZoneMeasure = Literal["inside", "entries", "exits", "dwell_s"]


class Zone:
    """A polygon: tracks inside now, entries and exits (all, or in the last window_s), and
    dwell (the longest time a track now inside has been inside). A track first seen inside
    has entered (from out of view); a track dropped while inside has left."""

    def __init__(self, points: list[Point], label: str | None, anchor: Anchor,
                 window_s: float | None) -> None:
        self._polygon, self._label, self._anchor = Polygon(points), label, anchor
        self._entered: dict[int, float] = {}  # track id -> time it entered
        self.entries, self.exits = _Events(window_s), _Events(window_s)

    def update(self, tracks: Tracks) -> dict[ZoneMeasure, float]:
        now, current = tracks.time, {t.track_id: t for t in tracks.of(self._label)}
        for track_id in [i for i in self._entered if i not in current]:
            del self._entered[track_id]
            self.exits.add(now)
        for t in current.values():
            if t.last_seen != now:
                continue  # unseen this frame: where it is is a guess; decide when it is seen
            inside = self._polygon.contains(anchor_point(t.box, self._anchor))
            if inside and t.track_id not in self._entered:
                self._entered[t.track_id] = now
                self.entries.add(now)
            elif not inside and t.track_id in self._entered:
                del self._entered[t.track_id]
                self.exits.add(now)
        return {"inside": len(self._entered), "entries": self.entries.count(now),
                "exits": self.exits.count(now),
                "dwell_s": round(max((now - s for s in self._entered.values()), default=0.0),
                                 3)}


LineMeasure = Literal["in", "out"]


class Line:
    """Crossings of the segment start-end by a track's anchor: `in` from its left to its
    right (walking from start to end, as seen in the image), `out` the other way."""

    def __init__(self, start: Point, end: Point, label: str | None, anchor: Anchor,
                 window_s: float | None) -> None:
        self._start, self._end, self._label, self._anchor = start, end, label, anchor
        self._last: dict[int, Point] = {}
        self.crossed_in, self.crossed_out = _Events(window_s), _Events(window_s)

    def update(self, tracks: Tracks) -> dict[LineMeasure, int]:
        now = tracks.time
        alive = {t.track_id for t in tracks.of(self._label)}
        self._last = {i: p for i, p in self._last.items() if i in alive}
        for t in tracks.seen_now(self._label):
            point = anchor_point(t.box, self._anchor)
            before = self._last.get(t.track_id)
            self._last[t.track_id] = point
            if before is not None and segments_cross(before, point, self._start, self._end):
                inward = side(self._start, self._end, point) > 0
                (self.crossed_in if inward else self.crossed_out).add(now)
        return {"in": self.crossed_in.count(now), "out": self.crossed_out.count(now)}
