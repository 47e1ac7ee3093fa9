"""`oricf bench detector`: what the service costs over in-process inference.

On 640x480 frames of the pedestrian video, in one run and interleaved frame by frame:
- median latency of in-process inference (the model class called directly),
- median latency of Detect through the service (a separate process on localhost) with raw
  rgb8 frames and with JPEG frames,
- throughput of DetectStream against in-process throughput.
Targets: the service adds at most 3 ms median per frame over in-process inference, and
DetectStream sustains at least 90% of in-process throughput.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import grpc
import numpy as np

from oricf.bench.common import load_frames, median_ms, print_table, served
from oricf.config import load_config, shipped_service_config
from oricf.models.declaration import DetectionTask
from oricf.services.detector.service import Detector, DetectorConfig
from oricf.store import ModelStore
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc


def request_for(frame: np.ndarray, encoding: str, frame_id: int = 0
                ) -> detector_pb2.DetectRequest:
    if encoding == "jpeg":
        data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
    else:
        data = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB).tobytes()
    image = common_pb2.Image(data=data, encoding=encoding, width=frame.shape[1],
                             height=frame.shape[0])
    return detector_pb2.DetectRequest(image=image, labels=["person"], frame_id=frame_id)


def timed(call: object) -> float:
    started = time.perf_counter()
    call()  # type: ignore[operator]
    return time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench detector", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=200, help="frames per measurement")
    parser.add_argument("--config", type=Path, default=shipped_service_config("detector"),
                        help="detector YAML for both the in-process model and the service")
    args = parser.parse_args(argv)

    config = load_config(args.config, DetectorConfig)
    model = Detector(config, ModelStore()).model
    model.load()
    frames = load_frames(args.frames)
    task = model.declaration.task
    assert isinstance(task, DetectionTask)
    min_score = config.detection.min_score or task.min_score
    person = np.array([0])

    def in_process(frame: np.ndarray) -> object:
        return model.detect(model.prepare(frame), min_score, person)

    rgb = [request_for(f, "rgb8", i) for i, f in enumerate(frames)]
    jpeg = [request_for(f, "jpeg", i) for i, f in enumerate(frames)]

    with served("detector", "--config", str(args.config)) as (address, _):
        channel = grpc.insecure_channel(address, options=[
            ("grpc.max_send_message_length", 64 << 20)])
        stub = detector_pb2_grpc.DetectorStub(channel)
        for warm in rgb[:10]:
            stub.Detect(warm, timeout=10)
        latency: dict[str, list[float]] = {"in-process": [], "Detect rgb8": [], "Detect jpeg": []}
        for frame, raw_request, jpeg_request in zip(frames, rgb, jpeg, strict=True):
            latency["in-process"].append(timed(lambda f=frame: in_process(f)))
            latency["Detect rgb8"].append(timed(lambda r=raw_request: stub.Detect(r, timeout=10)))
            latency["Detect jpeg"].append(timed(lambda r=jpeg_request: stub.Detect(r, timeout=10)))

        # Throughput, alternating the two ways three times and keeping each one's median.
        inproc_fps, stream_fps = [], []
        for _ in range(3):
            inproc_fps.append(len(frames) / timed(
                lambda: [in_process(f) for f in frames]))
            stream_fps.append(len(frames) / timed(lambda: _drain(stub.DetectStream(iter(rgb)))))
        channel.close()
    model.close()
    report(latency, inproc_fps, stream_fps, len(frames))
    return 0


def _drain(responses: Iterator[detector_pb2.DetectResponse]) -> None:
    for response in responses:
        if response.HasField("error"):
            raise RuntimeError(response.error.message)


def report(latency: dict[str, list[float]], inproc_fps: list[float], stream_fps: list[float],
           frames: int) -> None:
    base = median_ms(latency["in-process"])
    rows = [[name, f"{median_ms(values):.2f}", f"{median_ms(values) - base:+.2f}",
             f"{median_ms(values) / base:.2f}x"] for name, values in latency.items()]
    print_table(f"Latency per 640x480 frame (median of {frames}, interleaved)",
                ["path", "median ms", "added ms", "ratio"], rows)
    inproc, stream = sorted(inproc_fps)[1], sorted(stream_fps)[1]
    print_table("Throughput (median of 3 alternating runs)", ["path", "frames/s", "ratio"],
                [["in-process", f"{inproc:.1f}", "1.00"],
                 ["DetectStream rgb8", f"{stream:.1f}", f"{stream / inproc:.2f}"]])
    added = median_ms(latency["Detect rgb8"]) - base
    print(f"\nservice adds {added:.2f} ms median per rgb8 frame (target <= 3 ms); "
          f"DetectStream sustains {stream / inproc:.0%} of in-process throughput "
          f"(target >= 90%)")
