"""`oricf bench tracking`: how well people are counted, frame by frame and through tracks.

The real detector service (the shipped YAML: YOLOX-Nano) runs on every frame of vtest.avi
(795 frames, 10 fps) over gRPC, asked for people from score 0.1 as a `track` route asks.
Two counts per frame are compared with people counted by hand in two sets of 40 frames
(tests/data/vtest_people_counts.yaml): the tuning set, on which the tracker's defaults were
chosen, and the held-out set, never used to choose any parameter; each is reported apart.
- raw: the route's `count` step on the detections at the detector's default score (what a
  route without tracking counts; the same boxes a call at that score gets, since
  suppression keeps a box only against higher-scored ones);
- tracked: the `track` and `count_tracks` steps with their defaults, on frame times of the
  video's own clock; and the same with ByteTrack's published settings (docs/tracking.md).
For each: the mean absolute error against the hand counts, and flicker: the share of
consecutive frame pairs within 0.2 s of a counted frame (taken to show the same people)
whose count changes.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from oricf.bench.common import print_table, shipped_detector_model
from oricf.config import REPO_ROOT
from oricf.gateway.components import PostSteps
from oricf.gateway.config import PostStep
from oricf.gateway.methods.detect import detections
from oricf.gateway.post.count_tracks import CountTracksStep
from oricf.gateway.post.track import Track, TrackStep
from oricf.gateway.values import Record
from oricf.imaging import Detection
from oricf.models.declaration import DetectionTask
from oricf.services.local import local_service, service_config
from oricf.store import ModelStore
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from oricf.yamlfile import read_yaml

HAND_COUNTS = REPO_ROOT / "tests" / "data" / "vtest_people_counts.yaml"
TRACK_MIN_SCORE = 0.1
FLICKER_SPAN = 2  # frames either side of a counted frame


@dataclass(frozen=True)
class Quality:
    mae: float
    flicker: float


@dataclass(frozen=True)
class CountQuality:
    raw: Quality
    tracked: Quality
    published: Quality  # tracked with ByteTrack's published settings


@dataclass(frozen=True)
class HandCounts:
    tuning: dict[int, int]    # frame -> people; the tracker's defaults were chosen on these
    held_out: dict[int, int]  # never used to choose any parameter
    fps: float


@dataclass(frozen=True)
class Result:
    tuning: CountQuality
    held_out: CountQuality
    frames: int
    fps: float


# ByteTrack's own settings as near as this tracker has them: a new track confirmed on its
# second match, at track_thresh + 0.1 (here on the mean of its two scores, in ByteTrack on
# the first), second-stage IoU 0.5, no still rule; the count holds a track for 0.5 s.
# Shown beside the defaults, which were chosen on the tuning set.
PUBLISHED = (TrackStep(labels=["person"], new_score=0.6, low_match_iou=0.5, min_hits=2,
                       still_s=None),
             CountTracksStep(label="person", hold_s=0.5))


def video_frames() -> Iterator[np.ndarray]:
    capture = cv2.VideoCapture(str(ModelStore().path("vtest-video", "vtest.avi")))
    try:
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            yield frame
    finally:
        capture.release()


def detect_all(min_score: float) -> list[list[Detection]]:
    """People in every frame, from the real detector service over gRPC (raw frames, as an
    onboard route sends them)."""
    import grpc

    found = []
    with local_service("detector", service_config("detector")) as host:
        channel = grpc.insecure_channel(f"127.0.0.1:{host.port}")
        stub = detector_pb2_grpc.DetectorStub(channel)
        for frame in video_frames():
            image = common_pb2.Image(data=frame.tobytes(), encoding="bgr8",
                                     width=frame.shape[1], height=frame.shape[0])
            response = stub.Detect(detector_pb2.DetectRequest(
                image=image, labels=["person"], min_score=min_score), timeout=30)
            found.append(detections(response).detections)
        channel.close()
    return found


def raw_counts(found: list[list[Detection]], min_score: float) -> list[int]:
    return [sum(1 for d in frame if d.score >= min_score) for frame in found]


def tracked_counts(found: list[list[Detection]], fps: float,
                   track: TrackStep | None = None,
                   count: CountTracksStep | None = None) -> list[int]:
    """The `track` and `count_tracks` steps as a route runs them, on the video's clock."""
    now = [0.0]
    tracking = Track(track or TrackStep(labels=["person"]), clock=lambda: now[0])
    counting = PostSteps([PostStep(count_tracks=count or CountTracksStep(label="person"))])
    counts: list[int] = []
    for index, frame in enumerate(found):
        now[0] = index / fps
        record: Record = {"detections": frame}
        tracking.run(record)
        counting.run(record)
        counts.append(record["count"])
    return counts


def quality(counts: list[int], hand: dict[int, int]) -> Quality:
    errors = [abs(counts[f] - n) for f, n in hand.items()]
    changes = []
    for f in hand:
        span = range(max(0, f - FLICKER_SPAN), min(len(counts) - 1, f + FLICKER_SPAN))
        changes += [counts[i] != counts[i + 1] for i in span]
    return Quality(sum(errors) / len(errors), sum(changes) / len(changes))


def hand_counts(path: Path = HAND_COUNTS) -> HandCounts:
    data = read_yaml(path)

    def frames(key: str) -> dict[int, int]:
        return {int(k): int(v) for k, v in data[key].items()}

    return HandCounts(frames("counts"), frames("held_out"), float(data["fps"]))


def measure(found: list[list[Detection]] | None = None) -> Result:
    hand = hand_counts()
    found = found if found is not None else detect_all(TRACK_MIN_SCORE)
    task = shipped_detector_model().task
    assert isinstance(task, DetectionTask), "the shipped detector declares no detection task"
    raw = raw_counts(found, task.min_score)
    tracked = tracked_counts(found, hand.fps)
    published = tracked_counts(found, hand.fps, *PUBLISHED)

    def on(frames: dict[int, int]) -> CountQuality:
        return CountQuality(quality(raw, frames), quality(tracked, frames),
                            quality(published, frames))

    return Result(on(hand.tuning), on(hand.held_out), len(found), hand.fps)


def print_set(title: str, result: CountQuality) -> None:
    raw = result.raw
    print_table(title,
                ["count", "mean abs. error", "flicker", "ratio of error", "ratio of flicker"],
                [["raw", f"{raw.mae:.2f}", f"{raw.flicker:.1%}", "1.00", "1.00"],
                 *([name, f"{q.mae:.2f}", f"{q.flicker:.1%}", f"{q.mae / raw.mae:.2f}",
                    f"{q.flicker / raw.flicker:.2f}"]
                   for name, q in (("tracked", result.tracked),
                                   ("tracked, ByteTrack's settings", result.published)))])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="oricf bench tracking", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_args(argv)
    result = measure()
    hand = hand_counts()
    print(f"{result.frames} frames at {result.fps:g} fps; counted by hand "
          f"({HAND_COUNTS.relative_to(REPO_ROOT)}): {len(hand.tuning)} in the tuning set, "
          f"{len(hand.held_out)} held out")
    print_set(f"People counted: raw (per frame) vs tracked, tuning set ({len(hand.tuning)} "
              "frames: the defaults were chosen on these)", result.tuning)
    print_set(f"People counted: raw (per frame) vs tracked, held-out set "
              f"({len(hand.held_out)} frames: never used to choose a parameter)",
              result.held_out)


if __name__ == "__main__":
    main()
