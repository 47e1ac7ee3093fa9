"""`oricf bench gateway`: what the gateway adds per frame, and robot CPU onboard vs offloaded.

Real processes on a private DDS domain: `oricf serve detector` and `oricf gateway` (the
people_qa pipeline, its people route counting only), and this process as the camera,
publishing 640x480 vtest.avi frames on camera/image_raw (or, with --input compressed, as
JPEG sensor_msgs/CompressedImage, which the gateway passes on without decoding).

1. Latency, interleaved frame by frame: publish -> /human_counter through the gateway, and a
   direct Detect call with the same raw frame. Medians; the difference is what the gateway
   adds (DDS both ways, conversion, the worker hand-off).
2. Robot-side CPU per processed frame (utime + stime from /proc over --frames frames at
   --fps): onboard = gateway + detector processes; offloaded = the gateway process only (the
   detector would run on the edge server). Offloaded is measured with raw frames and again with
   a gateway sending JPEG (what a remote endpoint would use). The detector runs on this
   machine in every case; it is simply not counted as robot CPU when offloaded. Onboard is
   measured with the shipped detector (2 onnxruntime threads, whose idle workers spin) and
   with a 1-thread detector (no spinning: the least CPU an onboard detector needs).
"""

from __future__ import annotations

import argparse
import os
import queue
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from oricf.bench.common import median_ms, print_table, served
from oricf.config import config_dir, deep_merge, read_yaml
from oricf.gateway.dds import DDS_PROFILE
from oricf.gateway.values import Frame
from oricf.imaging import encode_image
from oricf.store import ModelStore
from oricf.v1 import detector_pb2, detector_pb2_grpc

FRAME_SIZE = (640, 480)
COMPRESSED_TOPIC = "camera/compressed"
JPEG_QUALITY = 80
PIPELINE = config_dir() / "pipelines" / "people_qa.yaml"
TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (fields 14 and 15 of /proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def load_frames(count: int) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(ModelStore().path("vtest-video", "vtest.avi")))
    frames: list[np.ndarray] = []
    while len(frames) < count:
        ok, frame = capture.read()
        if not ok:
            capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            continue
        frames.append(cv2.resize(frame, FRAME_SIZE))
    capture.release()
    return frames


def overlay(detector: str, transport: str, compressed: bool) -> dict[str, Any]:
    """The people route counting only (no annotated image), at the given placement."""
    source = ({"topic": COMPRESSED_TOPIC, "type": "sensor_msgs/CompressedImage"} if compressed
              else {"topic": "camera/image_raw", "type": "sensor_msgs/Image"})
    return {"endpoints": {"detector": {"address": detector, "deadline_ms": 2000,
                                       "image": {"transport": transport, "jpeg_quality": 80}}},
            "routes": {"people": {
                "input": source,
                "post": [{"count": {"label": "person", "into": "count"}}],
                "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32",
                             "from": "count"},
                            {"product": "people_count", "from": "count", "max_age_s": 5}]}}}


@contextmanager
def gateway(detector: str, transport: str, folder: Path, compressed: bool
            ) -> Iterator[subprocess.Popen[bytes]]:
    path = folder / f"{transport}.yaml"
    path.write_text(yaml.safe_dump(overlay(detector, transport, compressed)))
    command = [sys.executable, "-m", "oricf", "--log-level", "WARNING", "gateway", "--config",
               str(PIPELINE), "--overlay", str(path)]
    process = subprocess.Popen(command, env=os.environ.copy(), start_new_session=True)
    try:
        yield process
    finally:
        process.terminate()
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


class Camera:
    """This process's ROS side: publishes frames, receives counts."""

    def __init__(self, compressed: bool) -> None:
        import threading

        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CompressedImage, Image
        from std_msgs.msg import Int32

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("bench_camera", context=self.context)
        self.counts: queue.Queue[int] = queue.Queue()
        self.compressed = compressed
        self.publisher = self.node.create_publisher(
            CompressedImage if compressed else Image,
            COMPRESSED_TOPIC if compressed else "camera/image_raw", qos_profile_sensor_data)
        self.node.create_subscription(Int32, "/human_counter", self._on_count, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = threading.Thread(target=self.executor.spin, daemon=True)
        self.spinner.start()

    def _on_count(self, msg: Any) -> None:
        self.counts.put(int(msg.data))

    def prepare(self, frame: np.ndarray) -> tuple[Any, detector_pb2.DetectRequest]:
        """The message the camera publishes, and the same image as a direct Detect request."""
        from sensor_msgs.msg import CompressedImage

        from oricf.gateway.convert import image_from_pixels

        if not self.compressed:
            image = Frame.from_pixels(frame)
            msg = image_from_pixels(frame)
        else:
            image = Frame(encode_image(frame, "jpeg", JPEG_QUALITY), "jpeg")
            msg = CompressedImage(format="jpeg")
            msg.data = image.data
        return msg, detector_pb2.DetectRequest(image=image.to_proto(), labels=["person"])

    def count_of(self, msg: Any, timeout: float = 5.0) -> int | None:
        self.publisher.publish(msg)
        try:
            return self.counts.get(timeout=timeout)
        except queue.Empty:
            return None

    def warm_up(self, frame: Any, process: subprocess.Popen[bytes]) -> None:
        """Until the gateway answers (discovery done both ways), then forgets the extras."""
        deadline = time.monotonic() + 60
        while self.count_of(frame, timeout=0.5) is None:
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("the gateway did not answer")
        time.sleep(0.5)
        while not self.counts.empty():
            self.counts.get_nowait()

    def close(self) -> None:
        import rclpy

        self.executor.shutdown(timeout_sec=5)
        self.spinner.join(timeout=5)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def latency(camera: Camera, stub: Any, frames: list[tuple[Any, detector_pb2.DetectRequest]]
            ) -> tuple[float, float, int]:
    """(median gateway ms, median direct ms, frames that got no count), interleaved."""
    through, direct, lost = [], [], 0
    for i, (frame, request) in enumerate(frames):
        order = ("gateway", "direct") if i % 2 == 0 else ("direct", "gateway")
        for path in order:
            started = time.perf_counter()
            if path == "direct":
                stub.Detect(request, timeout=5)
                direct.append(time.perf_counter() - started)
            elif camera.count_of(frame) is None:
                lost += 1
            else:
                through.append(time.perf_counter() - started)
    return median_ms(through), median_ms(direct), lost


def cpu_per_frame(camera: Camera, frames: list[Any], fps: float,
                  pids: list[int]) -> list[float]:
    """CPU seconds per processed frame of each process, at a camera's pace."""
    before = [cpu_seconds(pid) for pid in pids]
    processed = 0
    period = 1.0 / fps
    next_at = time.monotonic()
    for frame in frames:
        next_at += period
        if camera.count_of(frame, timeout=2.0) is not None:
            processed += 1
        time.sleep(max(0.0, next_at - time.monotonic()))
    used = [cpu_seconds(pid) - b for pid, b in zip(pids, before, strict=True)]
    if processed < len(frames):
        print(f"note: {len(frames) - processed} of {len(frames)} frames got no count")
    return [u / max(processed, 1) for u in used]


def one_thread_detector(folder: Path) -> Path:
    """The shipped detector config with one onnxruntime thread (no idle worker spinning)."""
    data = deep_merge(read_yaml(config_dir() / "services" / "detector.yaml"),
                      {"model": {"threads": 1}})
    path = folder / "detector-1-thread.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def run(args: argparse.Namespace, folder: Path) -> None:
    os.environ.update({"ROS_DOMAIN_ID": str(random.randint(1, 100)),
                       "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                       "FASTRTPS_DEFAULT_PROFILES_FILE": str(DDS_PROFILE)})
    import grpc

    compressed = args.input == "compressed"
    cpu: dict[str, float] = {}
    camera = Camera(compressed)
    try:
        prepared = [camera.prepare(frame) for frame in load_frames(args.frames)]
        messages = [msg for msg, _ in prepared]
        with served("detector") as (address, detector), \
                grpc.insecure_channel(address) as channel:
            with gateway(address, "raw", folder, compressed) as raw:
                camera.warm_up(messages[0], raw)
                through, direct, lost = latency(camera, detector_pb2_grpc.DetectorStub(channel),
                                                prepared)
                cpu["gw raw 1"], cpu["det 2"] = cpu_per_frame(camera, messages, args.fps,
                                                              [raw.pid, detector.pid])
            with gateway(address, "jpeg", folder, compressed) as jpeg:
                camera.warm_up(messages[0], jpeg)
                (cpu["gw jpeg"],) = cpu_per_frame(camera, messages, args.fps, [jpeg.pid])
        with served("detector", "--config", str(one_thread_detector(folder))) as (address, det1), \
                gateway(address, "raw", folder, compressed) as raw:
            camera.warm_up(messages[0], raw)
            cpu["gw raw 2"], cpu["det 1"] = cpu_per_frame(camera, messages, args.fps,
                                                          [raw.pid, det1.pid])
    finally:
        camera.close()
    report(args, (through, direct, lost), cpu)


def report(args: argparse.Namespace, latencies: tuple[float, float, int],
           cpu: dict[str, float]) -> None:
    through, direct, lost = latencies
    kind = "raw bgr8" if args.input == "raw" else f"JPEG q{JPEG_QUALITY}"
    print_table(f"Latency per {FRAME_SIZE[0]}x{FRAME_SIZE[1]} {kind} frame, median of "
                f"{args.frames} (interleaved; {lost} frames without a count)",
                ["path", "median ms"],
                [["publish -> /human_counter (gateway)", f"{through:.1f}"],
                 [f"direct Detect call ({kind})", f"{direct:.1f}"],
                 ["added by the gateway", f"{through - direct:.1f}"]])
    onboard2 = cpu["gw raw 1"] + cpu["det 2"]
    onboard1 = cpu["gw raw 2"] + cpu["det 1"]
    offloaded = {"offloaded, transport raw": (cpu["gw raw 1"] + cpu["gw raw 2"]) / 2,
                 "offloaded, transport jpeg": cpu["gw jpeg"]}
    rows = [["onboard, detector 2 threads (shipped)", "gateway + detector",
             f"{onboard2 * 1e3:.2f}", "-", "-"],
            ["onboard, detector 1 thread", "gateway + detector", f"{onboard1 * 1e3:.2f}",
             "-", "-"]]
    for name, value in offloaded.items():
        cuts = [f"{(1 - value / onboard) * 100:.1f}%" for onboard in (onboard2, onboard1)]
        rows.append([name, "gateway", f"{value * 1e3:.2f}", *cuts])
    print_table(f"Robot-side CPU per processed frame at {args.fps:g} fps, {args.frames} frames "
                f"per phase (the detector alone: {cpu['det 2'] * 1e3:.1f} ms with 2 threads, "
                f"{cpu['det 1'] * 1e3:.1f} ms with 1)",
                ["placement", "robot processes", "CPU ms/frame", "cut vs 2 threads",
                 "cut vs 1 thread"], rows)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench gateway", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60, help="frames per phase")
    parser.add_argument("--fps", type=float, default=10.0, help="camera rate for the CPU phase")
    parser.add_argument("--input", choices=["raw", "compressed"], default="raw",
                        help="the camera publishes sensor_msgs/Image (raw bgr8) or "
                             "CompressedImage (JPEG, quality 80)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        run(args, Path(folder))
    return 0
