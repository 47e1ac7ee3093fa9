"""ByteTrack (Zhang et al., 2022) over one stream of detections.

Each frame: every track's box is moved on by its Kalman filter; detections at or above
`high_score` are matched to all tracks by IoU (an optimal assignment); then the tracks that
were seen in the previous frame and are still unmatched get a second chance with the
low-score detections (`low_score` up to `high_score`), which are often the same object
half hidden. A high-score detection left over starts a tentative track, confirmed once the
mean score of its last `min_hits` matches reaches `new_score` and dropped at its first
miss; a confirmed track that goes unseen for more than `max_age_s` is dropped. A confirmed
track that has stayed still for `still_s` is reported only while it scores at least
`still_score` (oricf.gateway.tracking.track says why). Only detections of the same label
are matched to a track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.gateway.tracking.track import Rules, Track, box_now
from oricf.imaging import Box, Detection


class TrackerConfig(Schema):
    labels: list[str] = Field(default_factory=list, description="labels to track; empty: all")
    high_score: float = Field(0.5, gt=0, le=1, description="first-stage detections")
    low_score: float = Field(0.1, gt=0, le=1, description="second-stage detections from here")
    new_score: float = Field(0.6, gt=0, le=1, description="mean score of a new track's "
                                                          "last min_hits matches that "
                                                          "confirms it")
    match_iou: float = Field(0.2, gt=0, le=1, description="least IoU of a first-stage match")
    low_match_iou: float = Field(0.3, gt=0, le=1, description="least IoU of a second-stage "
                                                              "match")
    min_hits: int = Field(2, ge=1, le=100, description="matches before a track is confirmed")
    max_age_s: float = Field(1.0, gt=0, le=3600, description="unseen this long: dropped")
    still_s: float | None = Field(5.0, gt=0, le=3600, description="a track still this long "
                                                                  "is judged by still_score")
    still_motion: float = Field(0.1, ge=0, le=10, description="most a still track's centre "
                                                              "moves, in box heights")
    still_score: float = Field(0.7, gt=0, le=1, description="least mean score of a still "
                                                            "track that is reported")

    @model_validator(mode="after")
    def _ordered(self) -> TrackerConfig:
        if self.low_score > self.high_score:
            raise ValueError(f"low_score {self.low_score} is above high_score "
                             f"{self.high_score}")
        return self


@dataclass(frozen=True)
class TrackView:
    """A confirmed track as it stands after a frame."""

    track_id: int
    label: str
    box: Box                       # the last matched box, or the predicted one while unseen
    velocity: tuple[float, float]  # centre, pixels per second
    first_seen: float
    last_seen: float
    hits: int
    age_s: float                   # since the track started


# Farther out than any image's pixels (oricf.imaging.MAX_PIXELS), or smaller than a
# hundredth of a pixel: such a box is garbage, and its numbers would overflow or vanish.
MAX_COORDINATE = 1e8
MIN_SIZE = 0.01


def in_range(values: tuple[float, ...]) -> bool:
    """Every value a finite number of pixels within MAX_COORDINATE."""
    return all(abs(v) <= MAX_COORDINATE for v in values)  # False for NaN


def usable(detection: Detection) -> bool:
    """A finite score and a box of at least MIN_SIZE within MAX_COORDINATE: anything else
    (a model behind the Open Inference Protocol may send it) would poison a track's filter."""
    b = detection.box
    coordinates = (b.x_min, b.y_min, b.x_max, b.y_max)
    return (math.isfinite(detection.score)
            and in_range(coordinates)
            and b.x_max - b.x_min >= MIN_SIZE and b.y_max - b.y_min >= MIN_SIZE)


def iou_matrix(a: list[Box], b: list[Box]) -> np.ndarray:
    if not a or not b:
        return np.zeros((len(a), len(b)))
    p = np.array([[x.x_min, x.y_min, x.x_max, x.y_max] for x in a])[:, None, :]
    q = np.array([[x.x_min, x.y_min, x.x_max, x.y_max] for x in b])[None, :, :]
    w = np.clip(np.minimum(p[..., 2], q[..., 2]) - np.maximum(p[..., 0], q[..., 0]), 0, None)
    h = np.clip(np.minimum(p[..., 3], q[..., 3]) - np.maximum(p[..., 1], q[..., 1]), 0, None)
    inter = w * h
    area = lambda r: (r[..., 2] - r[..., 0]) * (r[..., 3] - r[..., 1])  # noqa: E731
    union = area(p) + area(q) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def match(tracks: list[Track], detections: list[Detection], least_iou: float
          ) -> list[tuple[int, int]]:
    """(track index, detection index) pairs of the optimal assignment by IoU, each pair of
    one label and at least `least_iou`."""
    iou = iou_matrix([t.motion.box for t in tracks], [d.box for d in detections])
    if iou.size == 0:
        return []
    # Imported on the first match, not with the gateway: most pipelines never track.
    from scipy.optimize import linear_sum_assignment

    same = np.array([[t.label == d.label for d in detections] for t in tracks])
    iou = np.where(same, iou, 0.0)
    rows, cols = linear_sum_assignment(-iou)
    return [(r, c) for r, c in zip(rows, cols, strict=True) if iou[r, c] >= least_iou]


class ByteTracker:
    """Tracks over one stream; `update` once per frame, in time order."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config
        self._labels = set(config.labels)
        self._rules = Rules(config.min_hits, config.new_score, config.still_s,
                            config.still_motion, config.still_score)
        self._tracks: list[Track] = []
        self._next_id = 1
        self._now = 0.0

    def update(self, detections: list[Detection], now: float) -> list[Detection]:
        """This frame's detections that belong to reported tracks (confirmed, and not a
        still thing that scores weakly), each with its track id and velocity."""
        c = self.config
        wanted = [d for d in detections
                  if (not self._labels or d.label in self._labels) and usable(d)]
        high = [d for d in wanted if d.score >= c.high_score]
        low = [d for d in wanted if c.low_score <= d.score < c.high_score]
        for track in self._tracks:
            track.predict(now)
        matched: dict[int, Detection] = {}  # track index -> its detection, marked
        pairs = match(self._tracks, high, c.match_iou)
        for t, d in pairs:
            matched[t] = self._tracks[t].hit(high[d], now)
        used_high = {d for _, d in pairs}
        second = [t for t in range(len(self._tracks))
                  if t not in matched and self._tracks[t].seen_last_frame]
        for t, d in match([self._tracks[t] for t in second], low, c.low_match_iou):
            matched[second[t]] = self._tracks[second[t]].hit(low[d], now)
        out = [det for t, det in matched.items() if self._tracks[t].reported(now)]
        self._forget(matched, now)
        out += self._start([d for i, d in enumerate(high) if i not in used_high], now)
        self._now = now
        return out

    def _start(self, leftovers: list[Detection], now: float) -> list[Detection]:
        """A tentative track for each high-score detection left over. As in ByteTrack,
        the first frame's confident ones are confirmed at once: with no earlier frame,
        there is nothing to wait for."""
        first_frame = self._next_id == 1 and not self._tracks
        out = []
        for new in leftovers:
            track = Track(self._next_id, new, now, self._rules)
            self._tracks.append(track)
            self._next_id += 1
            if first_frame and new.score >= self.config.new_score:
                track.confirmed = True
                out.append(replace(new, track_id=track.track_id, velocity=(0.0, 0.0)))
        return out

    def _forget(self, matched: dict[int, Detection], now: float) -> None:
        keep = []
        for i, track in enumerate(self._tracks):
            track.seen_last_frame = i in matched
            if track.seen_last_frame or (track.confirmed and
                                         now - track.last_seen <= self.config.max_age_s):
                keep.append(track)
        self._tracks = keep

    def confirmed(self) -> list[TrackView]:
        """Every reported track still kept, seen this frame or not."""
        return [view(t) for t in self._tracks if t.reported(self._now)]


def view(track: Track) -> TrackView:
    return TrackView(track.track_id, track.label, box_now(track), track.motion.velocity,
                     track.first_seen, track.last_seen, track.hits,
                     track.predicted_at - track.first_seen)
