"""`oricf bench rtsp`: from an RTSP camera to a JSON line, as the gateway runs it without ROS.

A camera on this machine (bench/rtsp_camera.py: frames of vtest.avi stamped with the time
they were sent, H.264 by FFmpeg, served by GStreamer's RTSP server) feeds the gateway's
people route (the video source, the detector service in a process of its own, the count,
the JSON-lines sink) in this process. Per camera frame rate it prints the frames decoded
and the counts written per second, the age of a frame when its count is written (median,
90th percentile: capture, encoding, RTSP, decoding, detection, counting), and the CPU this
process spends (the gateway's share: decoding the stream, converting, calling, writing) per
frame decoded and as a share of one core. Needs scripts/setup.sh --dev (ffmpeg, GStreamer).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from oricf.bench.common import print_table, served
from oricf.bench.entry import need_tools
from oricf.bench.rtsp_camera import PACKAGES, SYSTEM_PYTHON, RtspCamera
from oricf.bench.stamp import age_ms
from oricf.config import config_dir, read_yaml
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, parse_pipeline
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sinks.jsonl import JsonLines
from oricf.gateway.sources.video_source import VideoSource
from oricf.gateway.values import Record
from oricf.store import ModelStore

WARMUP_S = 5.0


@dataclass
class Lines(Emitter):
    """The JSON-lines sink, noting when each count was written and how old its frame was."""

    sink: JsonLines = field(default_factory=JsonLines)
    ages_ms: list[float] = field(default_factory=list)
    measuring: bool = False

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sink.write(str(record.get("route")), output, value)
        if self.measuring:
            self.ages_ms.append(age_ms(record["image"].pixels(), time.time()))


def pipeline_path() -> Path:
    """The pipeline the benchmark runs, its camera replaced by an RTSP stream."""
    return config_dir() / "pipelines" / "people_video.yaml"


def cpu_s() -> float:
    usage = os.times()
    return usage.user + usage.system


def measure(detector: str, fps: float, seconds: float) -> list[str]:
    path = pipeline_path()
    data = read_yaml(path)
    with RtspCamera() as camera:
        camera.play_stamped(ModelStore().path("vtest-video", "vtest.avi"), fps)
        data["endpoints"]["detector"]["address"] = detector
        route = data["routes"]["people"]
        route["input"] = {"url": camera.url}
        route["outputs"] = [{"jsonl": os.devnull, "from": "count"}]
        config = parse_pipeline(data, f"{path} (bench)", path.parent)
        lines = Lines()
        pipeline = Pipeline(config, lines)
        source = VideoSource("people", config.routes["people"].input,
                             lambda load: pipeline.submit("people", load), lambda route: None)
        pipeline.start()
        source.start()
        try:
            time.sleep(WARMUP_S)  # the stream opened, the first frames drained
            frames0, cpu0, lines.measuring = source.frames, cpu_s(), True
            time.sleep(seconds)
            frames, cpu = source.frames - frames0, cpu_s() - cpu0
            written = len(lines.ages_ms)
        finally:
            lines.measuring = False
            source.stop()
            pipeline.stop()
            lines.sink.close()
    ages = sorted(lines.ages_ms) or [float("nan")]
    return [f"{fps:g}", f"{frames / seconds:.1f}", f"{written / seconds:.1f}",
            f"{statistics.median(ages):.0f}", f"{ages[int(0.9 * (len(ages) - 1))]:.0f}",
            f"{cpu / max(frames, 1) * 1e3:.1f}", f"{cpu / seconds * 100:.0f}%"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench rtsp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20, help="measured, per frame rate")
    parser.add_argument("--fps", type=float, nargs="+", default=[10, 25],
                        help="camera frame rates")
    args = parser.parse_args(argv)
    need_tools(("ffmpeg", SYSTEM_PYTHON), PACKAGES, "oricf bench rtsp")  # before any model loads
    with served("detector") as (detector, _):
        rows = [measure(detector, fps, args.seconds) for fps in args.fps]
    print_table(f"RTSP camera (H.264 768x576) -> people count -> JSON line, "
                f"{args.seconds:g} s per rate",
                ["camera fps", "decoded/s", "lines/s", "age median ms", "age p90 ms",
                 "gateway CPU ms/frame", "CPU of a core"], rows)
    return 0
