"""track: {labels: [person], min_hits: 2, max_age_s: 1.0, ...} follows objects from frame to
frame (ByteTrack, oricf.gateway.tracking.bytetrack). `detections` becomes the detections of
reported tracks (confirmed, and not a still thing that scores weakly), each with its
track_id and velocity; `into` (default `tracks`) gets every reported track still kept, seen
this frame or not, with the frame's time, for the steps that measure over tracks
(count_tracks, seen_tracks, zone, line).

The tracker's state lives as long as the route. Times are the gateway's monotonic clock
when the frame is post-processed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from oricf.gateway.post.base import Step
from oricf.gateway.tracking.bytetrack import ByteTracker, TrackerConfig
from oricf.gateway.tracking.measures import Tracks
from oricf.gateway.values import Record


class TrackStep(TrackerConfig):
    into: str = "tracks"


def build(step: TrackStep, clock: Callable[[], float] = time.monotonic) -> Step:
    tracker = ByteTracker(step)
    lock = threading.Lock()  # one frame at a time, in time order

    def run(record: Record) -> None:
        with lock:
            now = clock()
            record["detections"] = tracker.update(record["detections"], now)
            record[step.into] = Tracks(now, tracker.confirmed())

    return Step(frozenset({"detections"}), step.into, run)
