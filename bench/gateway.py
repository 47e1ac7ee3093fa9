"""`oricf bench gateway`: what the gateway adds per frame, and robot CPU and energy onboard
vs offloaded.

Real processes on a private DDS domain: `oricf serve detector` and `oricf gateway` (the
people_qa pipeline, its people route counting only), and this process as the camera,
publishing 640x480 vtest.avi frames as raw bgr8 sensor_msgs/Image on camera/image_raw and
(--input both, the default) then as JPEG sensor_msgs/CompressedImage, which the gateway passes
on without decoding. For each input:

1. Latency, interleaved frame by frame: publish -> /human_counter through the gateway, and a
   direct Detect call with the same frame. Medians; the difference is what the gateway adds
   (DDS both ways, reading the frame, publishing the count).
2. Robot-side CPU per processed frame (each process's CPU-time clock over --frames frames
   at --fps; the median of 5 consecutive parts): onboard = gateway + detector processes;
   offloaded = the gateway process only (the detector would run on the edge server).
   Each gateway runs the shipped placement overlay, with only the detector's address
   changed: configs/pipelines/placement/onboard.yaml (raw transport) and edge.yaml (JPEG
   transport and the edge deadline: the robot pays the encoding of raw frames,
   CompressedImage input passes as is). Offloaded is also shown with raw transport (the
   onboard gateway's figure). The detector runs on this machine in every case; it is simply
   not counted as robot CPU when offloaded. Onboard is measured with the shipped detector
   config and with the other thread count (1 or 2).
   The same onboard gateway tracking people (`track` and `count_tracks`) is measured
   beside it, with the post steps timed alone (oricf.bench.gateway_track); and serving
   the live view, with nobody watching and with one viewer (oricf.bench.gateway_view).
3. Estimated energy per frame: the power model in oricf.bench.gateway_report (CPU-seconds x
   watts per busy core, plus radio bytes x joules per bit when offloaded; both are flags).
4. The offloaded gateway's thread wake-ups per frame, what one wake-up costs a process on
   this machine, and how much slower a short burst of work runs after a pause of the
   camera's period (asleep, and busy-waiting) than back to back (oricf.bench.wakeups): most
   of the offloaded CPU, and the part that differs most between machines (shared virtual
   ones charge far more for both).
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import os
import queue
import random
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from oricf.bench.common import (
    FRAME_SIZE,
    JPEG_QUALITY,
    detector_with_threads,
    load_frames,
    median_ms,
    served,
    shipped_detector_model,
    stop,
)
from oricf.bench.gateway_infer import infer_overlay
from oricf.bench.gateway_report import (
    InputResult,
    PowerModel,
    cost_table,
    latency_table,
    wakeup_note,
)
from oricf.bench.gateway_tracing import TracingRun, traces_to, tracing_table
from oricf.bench.gateway_track import post_cost, track_table, tracking_overlay
from oricf.bench.gateway_view import view_overlay, view_table, watching
from oricf.bench.wakeups import idle_note, idle_slowdown, wakeup_cost, wakeups_by_thread
from oricf.config import config_dir, read_yaml
from oricf.gateway.config import load_pipeline
from oricf.gateway.endpoints import EndpointConfig
from oricf.gateway.ros.dds import dds_profile
from oricf.gateway.values import Frame
from oricf.imaging import encode_image
from oricf.launch.health import free_port
from oricf.v1 import detector_pb2, detector_pb2_grpc

COMPRESSED_TOPIC = "camera/compressed"
CHUNKS = 5  # the CPU phase's frames are measured in this many parts; the median is kept
_libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)


def pipeline_path() -> Path:
    """The pipeline the benchmark runs (with placement overlays)."""
    return config_dir() / "pipelines" / "people_qa.yaml"


def cpu_seconds(pid: int) -> float:
    """CPU time of a process so far, every thread's, to the nanosecond (its POSIX CPU-time
    clock; /proc's utime and stime count 10 ms ticks)."""
    clock = ctypes.c_int()
    if _libc.clock_getcpuclockid(pid, ctypes.byref(clock)) != 0:
        raise OSError(ctypes.get_errno(), f"no CPU clock for process {pid}")
    return time.clock_gettime(clock.value)


def placement(name: str) -> Path:
    """A shipped placement overlay: onboard or edge."""
    return pipeline_path().parent / "placement" / f"{name}.yaml"


def placement_detector(name: str) -> EndpointConfig:
    """The detector endpoint as a placement leaves it (transport, deadline)."""
    return load_pipeline(pipeline_path(), [placement(name)]).endpoints["detector"]


def overlay(detector: str, compressed: bool, transport: str | None = None,
            track: bool = False, view: int | None = None, infer: str | None = None
            ) -> dict[str, Any]:
    """Applied after the placement: the detector's address here (and another image
    transport if given), and the people route counting only (no annotated image), or
    tracking (track=True)."""
    source = ({"topic": COMPRESSED_TOPIC, "type": "sensor_msgs/CompressedImage"} if compressed
              else {"topic": "camera/image_raw", "type": "sensor_msgs/Image"})
    endpoint: dict[str, Any] = {"address": detector}
    if transport is not None:
        endpoint["image"] = {"transport": transport}
    counting = {"endpoints": {"detector": endpoint},
                "routes": {"people": {
                    "input": source,
                    "post": [{"count": {"label": "person", "into": "count"}}],
                    "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32",
                                 "from": "count"},
                                {"product": "people_count", "from": "count",
                                 "max_age_s": 5}]}}}
    if view is not None:
        counting = view_overlay(counting, view)
    if infer is not None:  # Infer with decoded detections on the models server there
        counting = infer_overlay(counting, infer)
    return tracking_overlay(counting) if track else counting


@contextmanager
def gateway(detector: str, where: str, folder: Path, compressed: bool,
            transport: str | None = None, track: bool = False, view: int | None = None,
            infer: str | None = None) -> Iterator[subprocess.Popen[bytes]]:
    """`oricf gateway` at placement `where` (onboard or edge), sending to detector (with
    another image transport if given; tracking if track; Infer with decoded detections on
    the models server at `infer` if given)."""
    path = folder / (f"{where}-{transport or 'placed'}{'-track' if track else ''}"
                     f"{'-view' if view else ''}{'-infer' if infer else ''}-here.yaml")
    path.write_text(yaml.safe_dump(overlay(detector, compressed, transport, track, view,
                                           infer)))
    command = [sys.executable, "-m", "oricf", "--log-level", "WARNING", "gateway", "--config",
               str(pipeline_path()), "--overlay", str(placement(where)), "--overlay", str(path)]
    process = subprocess.Popen(command, env=os.environ.copy(), start_new_session=True)
    try:
        yield process
    finally:
        stop(process, timeout=15)


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

        from oricf.demo.node import image_from_pixels

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


def latency(camera: Camera, stub: Any, frames: list[tuple[Any, detector_pb2.DetectRequest]],
            result: InputResult) -> None:
    """Median gateway and direct ms, frames that got no count, response size; interleaved."""
    through, direct, sizes, lost = [], [], [], 0
    for i, (frame, request) in enumerate(frames):
        order = ("gateway", "direct") if i % 2 == 0 else ("direct", "gateway")
        for path in order:
            started = time.perf_counter()
            if path == "direct":
                response = stub.Detect(request, timeout=5)
                direct.append(time.perf_counter() - started)
                sizes.append(response.ByteSize())
            elif camera.count_of(frame) is None:
                lost += 1
            else:
                through.append(time.perf_counter() - started)
    result.through_ms, result.direct_ms, result.lost = median_ms(through), median_ms(direct), lost
    result.response_bytes = statistics.median(sizes)


def cpu_per_frame(camera: Camera, frames: list[Any], fps: float,
                  pids: list[int]) -> list[float]:
    """CPU seconds per processed frame of each process, at a camera's pace: the median over
    CHUNKS consecutive parts of the frames (one noisy moment on a shared machine moves one
    part, not the figure); every process is measured over the same parts."""
    per_chunk: list[list[float]] = [[] for _ in pids]
    period = 1.0 / fps
    next_at = time.monotonic()
    missing = 0
    for chunk in np.array_split(np.arange(len(frames)), CHUNKS):
        before = [cpu_seconds(pid) for pid in pids]
        processed = 0
        for i in chunk:
            next_at += period
            if camera.count_of(frames[i], timeout=2.0) is not None:
                processed += 1
            time.sleep(max(0.0, next_at - time.monotonic()))
        missing += len(chunk) - processed
        for series, pid, b in zip(per_chunk, pids, before, strict=True):
            series.append((cpu_seconds(pid) - b) / max(processed, 1))
    if missing:
        print(f"note: {missing} of {len(frames)} frames got no count")
    return [statistics.median(series) for series in per_chunk]


def shipped_threads() -> int:
    return shipped_detector_model().backend.threads


def other_threads() -> int:
    """The onboard detector is also measured with this other thread count (1 or 2)."""
    return 2 if shipped_threads() == 1 else 1


def describe_transport(endpoint: EndpointConfig) -> str:
    image = endpoint.image
    return f"jpeg q{image.jpeg_quality}" if image.transport == "jpeg" else image.transport


def request_sizes(prepared: list[tuple[Any, detector_pb2.DetectRequest]]) -> dict[str, float]:
    """Median bytes of a Detect request per transport (what goes over the radio offloaded),
    JPEG at the edge placement's quality."""
    quality = placement_detector("edge").image.jpeg_quality

    def size(transport: str, request: detector_pb2.DetectRequest) -> int:
        image = request.image
        frame = Frame(image.data, image.encoding, image.width, image.height)
        copy = detector_pb2.DetectRequest()
        copy.CopyFrom(request)
        copy.image.CopyFrom(frame.to_proto(transport, quality))
        return copy.ByteSize()

    return {t: statistics.median(size(t, r) for _, r in prepared) for t in ("raw", "jpeg")}


def view_cost(camera: Camera, messages: list[Any], fps: float, detector: str,
              folder: Path, result: InputResult) -> None:
    """The onboard gateway's CPU with the live view: nobody watching, then one viewer."""
    port = free_port()
    with gateway(detector, "onboard", folder, camera.compressed, view=port) as viewed:
        camera.warm_up(messages[0], viewed)
        (result.cpu["gw view idle"],) = cpu_per_frame(camera, messages, fps, [viewed.pid])
        with watching(port) as rate:
            time.sleep(1)  # connected and subscribed
            (result.cpu["gw view"],) = cpu_per_frame(camera, messages, fps, [viewed.pid])
        result.view_images_per_s = rate[0]


def measure(args: argparse.Namespace, folder: Path, compressed: bool) -> InputResult:
    """Every phase for one kind of camera input."""
    import grpc

    result = InputResult("raw bgr8" if not compressed else f"JPEG q{JPEG_QUALITY}")
    cpu = result.cpu
    camera = Camera(compressed)
    try:
        prepared = [camera.prepare(frame) for frame in load_frames(args.frames)]
        result.request_bytes = request_sizes(prepared)
        messages = [msg for msg, _ in prepared]
        with served("detector") as (address, detector), \
                grpc.insecure_channel(address) as channel:
            with gateway(address, "onboard", folder, compressed) as raw:
                camera.warm_up(messages[0], raw)
                latency(camera, detector_pb2_grpc.DetectorStub(channel), prepared, result)
                cpu["gw raw 1"], cpu["det shipped"] = cpu_per_frame(camera, messages, args.fps,
                                                              [raw.pid, detector.pid])
            with gateway(address, "onboard", folder, compressed, track=True) as tracked:
                camera.warm_up(messages[0], tracked)
                cpu["gw track"], cpu["det track"] = cpu_per_frame(
                    camera, messages, args.fps, [tracked.pid, detector.pid])
            post_cost(detector_pb2_grpc.DetectorStub(channel), [r for _, r in prepared],
                      result)
            view_cost(camera, messages, args.fps, address, folder, result)
            with gateway(address, "onboard", folder, compressed, "shm") as shm:
                camera.warm_up(messages[0], shm)
                cpu["gw shm"], cpu["det shm"] = cpu_per_frame(camera, messages, args.fps,
                                                              [shm.pid, detector.pid])
            with gateway(address, "edge", folder, compressed) as jpeg:
                camera.warm_up(messages[0], jpeg)
                woken = wakeups_by_thread(jpeg.pid)
                (cpu["gw jpeg"],) = cpu_per_frame(camera, messages, args.fps, [jpeg.pid])
                woken = wakeups_by_thread(jpeg.pid) - woken
                result.edge_wakeups = {name: count / len(messages)
                                       for name, count in woken.most_common()}
            with served("models") as (models, _), \
                    gateway(address, "edge", folder, compressed, infer=models) as decoded:
                camera.warm_up(messages[0], decoded)
                (cpu["gw infer decoded"],) = cpu_per_frame(camera, messages, args.fps,
                                                           [decoded.pid])
        other = str(detector_with_threads(other_threads(), folder))
        with served("detector", "--config", other) as (address, det1), \
                gateway(address, "onboard", folder, compressed) as raw:
            camera.warm_up(messages[0], raw)
            cpu["gw raw 2"], cpu["det other"] = cpu_per_frame(camera, messages, args.fps,
                                                          [raw.pid, det1.pid])
    finally:
        camera.close()
    return result


def measure_tracing(args: argparse.Namespace, folder: Path, compressed: bool,
                    traced: bool) -> TracingRun:
    """--tracing: the onboard gateway and the detector, exporting traces or not."""
    import grpc

    run = TracingRun(traced)
    camera = Camera(compressed)
    try:
        prepared = [camera.prepare(frame) for frame in load_frames(args.frames)]
        messages = [msg for msg, _ in prepared]
        with traces_to(args.tracing if traced else None), served("detector") as (
                address, detector), grpc.insecure_channel(address) as channel, \
                gateway(address, "onboard", folder, compressed) as raw:
            camera.warm_up(messages[0], raw)
            result = InputResult("")
            latency(camera, detector_pb2_grpc.DetectorStub(channel), prepared, result)
            run.through_ms, run.direct_ms, run.lost = (result.through_ms, result.direct_ms,
                                                       result.lost)
            run.gateway_cpu_s, run.detector_cpu_s = cpu_per_frame(
                camera, messages, args.fps, [raw.pid, detector.pid])
    finally:
        camera.close()
    return run


def print_configuration(args: argparse.Namespace, power: PowerModel) -> None:
    detector = shipped_detector_model()
    path = pipeline_path()
    pipeline = read_yaml(path)
    placements = ", ".join(
        f"{where} (detector transport {describe_transport(endpoint)}, deadline "
        f"{endpoint.deadline_ms} ms)"
        for where, endpoint in ((w, placement_detector(w)) for w in ("onboard", "edge")))
    print(f"Configuration: {FRAME_SIZE[0]}x{FRAME_SIZE[1]} vtest.avi frames at {args.fps:g} fps, "
          f"{args.frames} frames per phase; camera input: {args.input}; gateway: {path.name} "
          f"people route (count only), executor threads "
          f"{pipeline.get('executor_threads', 1)}; placements: {placements}; "
          f"onboard detector: configs/services/detector.yaml (model {detector.name}, "
          f"{detector.backend.engine} {detector.backend.threads} threads) and the same with "
          f"{other_threads()} thread(s); "
          f"offloaded: the detector runs on this machine but is not counted as robot CPU.")
    print(f"Power model: {power.describe()}.")


def run(args: argparse.Namespace, folder: Path) -> None:
    os.environ.update({"ROS_DOMAIN_ID": str(random.randint(1, 100)),
                       "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                       "FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile())})
    power = PowerModel(args.watts_per_core, args.nj_per_bit)
    inputs = ["raw", "compressed"] if args.input == "both" else [args.input]
    if args.tracing:
        for kind in inputs:
            runs = [measure_tracing(args, folder, kind == "compressed", traced)
                    for traced in (False, True)]
            tracing_table(kind, runs, args.frames, args.fps, args.tracing)
        return
    results = [measure(args, folder, kind == "compressed") for kind in inputs]
    period_s = 1.0 / args.fps
    wakeup_s = wakeup_cost(args.fps)
    burst = idle_slowdown(period_s)
    print_configuration(args, power)
    for result in results:
        latency_table(result, args.frames)
    for result in results:
        cost_table(result, power, args.fps, (args.frames, CHUNKS),
                   (shipped_threads(), other_threads()))
        wakeup_note(result, wakeup_s)
        track_table(result)
        view_table(result, args.fps)
    idle_note(burst, period_s, "the gateway's work per frame")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench gateway", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60, help="frames per phase")
    parser.add_argument("--fps", type=float, default=10.0, help="camera rate for the CPU phase")
    parser.add_argument("--input", choices=["raw", "compressed", "both"], default="both",
                        help="the camera publishes sensor_msgs/Image (raw bgr8) or "
                             "CompressedImage (JPEG, quality 80), or each in turn")
    parser.add_argument("--watts-per-core", type=float, default=2.5,
                        help="power of one busy core of the robot computer (default 2.5 W, "
                             "a typical ARM SoC)")
    parser.add_argument("--nj-per-bit", type=float, default=7.5,
                        help="radio energy per bit sent or received when offloaded (default "
                             "7.5 nJ/bit, Wi-Fi is about 5-10)")
    parser.add_argument("--tracing", metavar="OTLP_ENDPOINT",
                        help="measure only what traces cost: the onboard gateway and detector "
                             "without traces, then exporting them to this OTLP endpoint "
                             "(e.g. Phoenix's http://127.0.0.1:6006; docs/tracing.md)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        run(args, Path(folder))
    return 0
