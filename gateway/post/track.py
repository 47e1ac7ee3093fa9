"""track: {labels: [person], min_hits: 2, max_age_s: 1.0, ...} follows objects from frame to
frame (ByteTrack, oricf.gateway.tracking.bytetrack). `detections` becomes the detections of
reported tracks (confirmed, and not a still thing that scores weakly), each with its
track_id and velocity; `into` (default `tracks`) gets every reported track still kept, seen
this frame or not, with the frame's time, for the steps that measure over tracks
(count_tracks, seen_tracks, zone, line).

The tracker's state lives as long as the route. Its time is the time each frame was taken
(values.FRAME_TIME: a recording's recorded time, a video file's position, a live camera's
stamp or arrival), so a replay or a file read faster or slower than real time tracks as it
did live; a record without one is timed when it is post-processed. A frame time that goes
back (a camera whose clock was reset) or leaps ahead by more than MAX_LEAP_S (a stamp
from another clock) restarts the tracks, logged; the route's time then goes on from where it
was, and new tracks get ids not given before, so measures over tracks (seen_tracks, zone,
line) see one time that never goes back and never count a track twice.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.tracking.bytetrack import ByteTracker, TrackerConfig
from oricf.gateway.tracking.measures import Tracks
from oricf.gateway.values import FRAME_TIME, Record
from oricf.imaging import Detection

log = logging.getLogger(__name__)

# Frame times further apart than this are judged to come from two clocks (a camera's stamps
# switching to the wall clock), not to be time that passed.
MAX_LEAP_S = 3600.0
# A frame this little older than the newest (out of order) is tracked at the newest time.
LATE_S = 0.5


class TrackStep(TrackerConfig):
    into: str = "tracks"


class RouteTracks:
    """A route's tracker on the route's time: the frames' times, shifted by a restart."""

    def __init__(self, step: TrackStep) -> None:
        self._step = step
        self._tracker = ByteTracker(step)
        self._last: float | None = None  # the newest frame time
        self._shift = 0.0     # route time - frame time
        self._first_id = 0    # added to the ids of the tracker since the last restart
        self._top_id = 0      # the highest id reported so far
        self._log = ThrottledLog(log)

    def update(self, detections: list[Detection], frame_time: float, route: str
               ) -> tuple[list[Detection], Tracks]:
        now = self._time(frame_time, route)
        found = [self._renumbered(d) for d in self._tracker.update(detections, now)]
        tracks = [self._renumbered(t) for t in self._tracker.confirmed()]
        self._top_id = max([self._top_id, *(t.track_id or 0 for t in [*found, *tracks])])
        return found, Tracks(now, tracks)

    def _time(self, frame_time: float, route: str) -> float:
        last = frame_time if self._last is None else self._last
        if -LATE_S <= frame_time - last < 0:
            return last + self._shift  # out of order: tracked at the newest time
        if not 0 <= frame_time - last <= MAX_LEAP_S:
            self._log.warning("leap", "route %s: frame time went %s by %.3f s: tracks start "
                              "again", route, "back" if frame_time < last else "ahead",
                              abs(frame_time - last))
            self._shift += last - frame_time
            self._tracker = ByteTracker(self._step)
            self._first_id = self._top_id
        self._last = frame_time
        return frame_time + self._shift

    def _renumbered(self, item: Any) -> Any:
        return replace(item, track_id=item.track_id + self._first_id) if self._first_id \
            else item


class Track(Step[TrackStep]):
    reads = frozenset({"detections"})

    def __init__(self, settings: TrackStep,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """`clock` times records that carry no FRAME_TIME."""
        super().__init__(settings)
        self.writes = settings.into
        self.tracking = RouteTracks(settings)
        self.clock = clock
        self.lock = threading.Lock()  # one frame at a time, in time order

    def run(self, record: Record) -> None:
        with self.lock:
            frame_time = record.get(FRAME_TIME)
            record["detections"], record[self.settings.into] = self.tracking.update(
                record["detections"], self.clock() if frame_time is None else frame_time,
                str(record.get("route", "")))


COMPONENT = StepKind("track", TrackStep, Track, rank=5)
