"""One track's state: its motion, its recent matches, and the two judgements made on them.

A track is confirmed when the mean score of its last `min_hits` matches reaches
`new_score`: one weak detection cannot confirm it, and a person the detector scores just
under a single cut-off in one frame and over it in the next still can. A confirmed track
is still when its centre has stayed within a small part of its height for `still_s`; a
still track whose mean score over that time stays under `still_score` is taken for part of
the scene (a post or a sign that looks a little like a person) and is not reported, though
it is kept, so its detections start no new track.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

from oricf.gateway.tracking.kalman import BoxFilter
from oricf.imaging import Box, Detection


@dataclass(frozen=True)
class Hit:
    time: float
    score: float
    x: float        # box centre
    y: float
    height: float


def hit_of(detection: Detection, now: float) -> Hit:
    b = detection.box
    return Hit(now, detection.score, (b.x_min + b.x_max) / 2, (b.y_min + b.y_max) / 2,
               b.y_max - b.y_min)


@dataclass(frozen=True)
class Rules:
    """What a track's matches are judged by (TrackerConfig's fields of the same names)."""

    min_hits: int
    new_score: float
    still_s: float | None
    still_motion: float
    still_score: float


class Track:
    def __init__(self, track_id: int, detection: Detection, now: float, rules: Rules) -> None:
        self.track_id = track_id
        self.label = detection.label
        self.motion = BoxFilter(detection.box)
        self.first_seen = self.last_seen = self.predicted_at = now
        self.hits = 1
        self.seen_last_frame = True
        self.box = detection.box
        self.rules = rules
        self.recent: deque[Hit] = deque([hit_of(detection, now)])
        self.confirmed = False
        self._judge_birth()

    def predict(self, now: float) -> None:
        self.motion.predict(now - self.predicted_at)
        self.predicted_at = max(now, self.predicted_at)

    def hit(self, detection: Detection, now: float) -> Detection:
        self.motion.update(detection.box)
        self.box = detection.box
        self.hits += 1
        self.last_seen = now
        self.recent.append(hit_of(detection, now))
        self._forget_old(now)
        self._judge_birth()
        return replace(detection, track_id=self.track_id, velocity=self.motion.velocity)

    def _forget_old(self, now: float) -> None:
        keep_s = self.rules.still_s or 0.0
        while (len(self.recent) > self.rules.min_hits
               and self.recent[0].time < now - keep_s):
            self.recent.popleft()

    def _judge_birth(self) -> None:
        if self.confirmed or self.hits < self.rules.min_hits:
            return
        last = list(self.recent)[-self.rules.min_hits:]
        self.confirmed = mean_score(last) >= self.rules.new_score

    def still(self, now: float) -> bool:
        """Seen over the last still_s, and its centre stayed within still_motion heights of
        where it is now all that time."""
        r = self.rules
        if r.still_s is None or now - self.first_seen < r.still_s:
            return False
        window = [h for h in self.recent if h.time >= now - r.still_s]
        if not window:
            return False
        last = self.recent[-1]
        reach = r.still_motion * last.height
        return all(math.hypot(h.x - last.x, h.y - last.y) <= reach for h in window)

    def reported(self, now: float) -> bool:
        """Confirmed, and not a still thing that scores weakly."""
        if not self.confirmed:
            return False
        if not self.still(now):
            return True
        assert self.rules.still_s is not None  # still() is False without it
        window = [h for h in self.recent if h.time >= now - self.rules.still_s]
        return mean_score(window) >= self.rules.still_score


def mean_score(hits: list[Hit]) -> float:
    return sum(h.score for h in hits) / len(hits)


def box_now(track: Track) -> Box:
    """The last matched box, or the predicted one while unseen."""
    return track.box if track.last_seen == track.predicted_at else track.motion.box
