"""One robot of `oricf bench edge` as a real gateway process: the gateway's routing core
(the people route: Detect with the person label, a count) fed 640x480 camera frames at
10 fps, sending them to the edge detector as JPEG, the newest frame winning while a call is
in flight. Prints one JSON line: what happened to the frames captured in the window.

    python -m oricf.bench.edge_robot --detector HOST:PORT --start-at EPOCH --seconds S
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from typing import Any

from oricf.bench.common import JPEG_QUALITY, load_frames
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, parse_pipeline
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame, Record

FPS = 10


def route(detector: str, deadline_ms: int) -> dict[str, Any]:
    return {
        "endpoints": {"detector": {
            "address": detector, "deadline_ms": deadline_ms,
            "image": {"transport": "jpeg", "jpeg_quality": JPEG_QUALITY}}},
        "routes": {"people": {
            "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
            "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
            "post": [{"count": {"label": "person", "into": "count"}}],
            "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32",
                         "from": "count"}]}},
    }


class Answers(Emitter):
    """The latency of each answered frame captured inside the window."""

    def __init__(self, start: float, end: float) -> None:
        self.start, self.end = start, end
        self.latencies: list[float] = []
        self._lock = threading.Lock()

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        captured = record["captured"]
        if self.start <= captured < self.end:
            with self._lock:
                self.latencies.append(time.time() - captured)


def run(detector: str, start_at: float, seconds: float, deadline_ms: int,
        offset: int) -> dict[str, Any]:
    frames = [Frame.from_pixels(f) for f in load_frames(20 + offset)[offset:]]
    end = start_at + seconds
    answers = Answers(start_at, end)
    pipeline = Pipeline(parse_pipeline(route(detector, deadline_ms), "bench edge robot"),
                        answers)
    pipeline.start()
    worker, people = pipeline.workers["people"], pipeline.routes["people"]
    counts: dict[str, tuple[int, int]] = {}  # "start"/"end" -> (dropped, call errors)
    captured = 0
    try:
        tick, i = time.time(), 0
        while tick < end + 0.5:  # frames until just past the window: its last ones answered
            for mark, at in (("start", start_at), ("end", end)):
                if tick >= at and mark not in counts:
                    counts[mark] = (worker.stats.dropped, people.stats.call_errors)
            captured += start_at <= tick < end
            frame = frames[i % len(frames)]
            pipeline.submit("people", lambda f=frame, t=tick: {"image": f, "captured": t})
            i += 1
            tick += 1 / FPS
            time.sleep(max(0.0, tick - time.time()))
    finally:
        pipeline.idle(deadline_ms / 1e3 + 1)
        pipeline.stop()
    (dropped0, errors0), (dropped1, errors1) = counts.get("start", (0, 0)), counts["end"]
    return {"captured": captured, "latencies": answers.latencies,
            "dropped": dropped1 - dropped0, "errors": errors1 - errors0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.edge_robot",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--detector", required=True, help="HOST:PORT of the edge detector")
    parser.add_argument("--start-at", type=float, required=True,
                        help="epoch seconds at which the measured window opens")
    parser.add_argument("--seconds", type=float, required=True, help="the window")
    parser.add_argument("--deadline-ms", type=int, default=1000)
    parser.add_argument("--offset", type=int, default=0, help="first video frame")
    args = parser.parse_args(argv)
    result = run(args.detector, args.start_at, args.seconds, args.deadline_ms, args.offset)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
