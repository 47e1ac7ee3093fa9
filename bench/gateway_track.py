"""The cost of the `track` step in `oricf bench gateway`: the people route as the benchmark
runs it (count only) against the same route tracking (`track` then `count_tracks` into the
count, detections asked for from score 0.1 as a tracking route does).

Two figures side by side, for each camera input: the gateway process's CPU per processed
frame (measured by the benchmark's CPU phase, with the detector's CPU beside it: weak
detections cost it nothing to return but more to send), and the post steps alone, timed
in this process on the detector's real answers for the same frames.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

from oricf.bench.common import print_table
from oricf.bench.gateway_report import InputResult
from oricf.bench.tracking import TRACK_MIN_SCORE
from oricf.gateway.components import PostSteps
from oricf.gateway.config import PostStep
from oricf.gateway.methods.detect import detections
from oricf.gateway.values import Record
from oricf.imaging import Detection
from oricf.v1 import detector_pb2

TRACKING: list[dict[str, Any]] = [{"track": {"labels": ["person"]}},
                                  {"count_tracks": {"label": "person", "into": "count"}}]
COUNTING: list[dict[str, Any]] = [{"count": {"label": "person", "into": "count"}}]


def tracking_overlay(overlay: dict[str, Any]) -> dict[str, Any]:
    """A benchmark gateway overlay with its people route tracking."""
    route = overlay["routes"]["people"]
    route["post"] = TRACKING
    route["call"] = {"min_score": TRACK_MIN_SCORE}
    return overlay


def _per_frame_us(steps: list[dict[str, Any]], frames: list[list[Detection]]) -> float:
    post = PostSteps([PostStep.model_validate(s) for s in steps])
    times = []
    for found in frames:
        record: Record = {"detections": found}
        started = time.perf_counter()
        post.run(record)
        times.append(time.perf_counter() - started)
    return statistics.median(times) * 1e6


def post_cost(stub: Any, requests: list[detector_pb2.DetectRequest], result: InputResult
              ) -> None:
    """Median microseconds per frame of the post steps, counting and tracking, on the
    detector's answers to these requests (at its default score, and from TRACK_MIN_SCORE)."""
    default, weak = [], []
    for request in requests:
        default.append(detections(stub.Detect(request, timeout=5)).detections)
        low = detector_pb2.DetectRequest()
        low.CopyFrom(request)
        low.min_score = TRACK_MIN_SCORE
        weak.append(detections(stub.Detect(low, timeout=5)).detections)
    result.post_us = {"count": _per_frame_us(COUNTING, default),
                      "track": _per_frame_us(TRACKING, weak)}


def track_table(result: InputResult) -> None:
    cpu, post = result.cpu, result.post_us
    rows = [["count (no tracking)", f"{cpu['gw raw 1'] * 1e3:.2f}",
             f"{cpu['det shipped'] * 1e3:.1f}", f"{post['count']:.0f}", "1.00"],
            ["track + count_tracks", f"{cpu['gw track'] * 1e3:.2f}",
             f"{cpu['det track'] * 1e3:.1f}", f"{post['track']:.0f}",
             f"{cpu['gw track'] / cpu['gw raw 1']:.2f}"]]
    print_table(f"The track step per processed frame, {result.kind} input, onboard (gateway "
                f"and detector CPU from the CPU phase; post steps timed alone, median)",
                ["people route", "gateway CPU ms", "detector CPU ms", "post steps us",
                 "gateway CPU ratio"], rows)
