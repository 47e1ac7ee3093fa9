"""Shared benchmark machinery: a real service process, timing loops, and result tables.

Benchmarks measure the things they compare side by side in one run, interleaved round by
round, because the machines they run on are shared and noisy; they report medians.
"""

from __future__ import annotations

import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import cv2
import grpc
import numpy as np
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.store import ModelStore

FRAME_SIZE = (640, 480)


def median_ms(seconds: Sequence[float]) -> float:
    return statistics.median(seconds) * 1e3


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_serving(address: str, process: subprocess.Popen[bytes], timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    with grpc.insecure_channel(address) as channel:
        stub = health_pb2_grpc.HealthStub(channel)
        while time.monotonic() < deadline:
            if process.poll() is not None:
                raise RuntimeError(f"the service exited with {process.returncode}")
            try:
                status = stub.Check(health_pb2.HealthCheckRequest(), timeout=1).status
                if status == health_pb2.HealthCheckResponse.SERVING:
                    return
            except grpc.RpcError:
                pass
            time.sleep(0.1)
    raise TimeoutError(f"{address} was not SERVING after {timeout} s")


@contextmanager
def served(service: str, *args: str) -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    """`oricf serve SERVICE` in a child process on a free local port, stopped on exit."""
    address = f"127.0.0.1:{free_port()}"
    command = [sys.executable, "-m", "oricf", "--log-level", "WARNING", "serve", service,
               "--listen", address, *args]
    process = subprocess.Popen(command, env=os.environ.copy())
    try:
        wait_serving(address, process)
        yield address, process
    finally:
        stop(process)


def stop(process: subprocess.Popen[bytes], timeout: float = 30) -> None:
    """SIGTERM (the process drains), SIGKILL if it takes longer than timeout."""
    process.terminate()
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def load_frames(count: int, size: tuple[int, int] = FRAME_SIZE) -> list[np.ndarray]:
    """count BGR frames of the pedestrian video resized to size, looping if needed."""
    capture = cv2.VideoCapture(str(ModelStore().path("vtest-video", "vtest.avi")))
    frames: list[np.ndarray] = []
    while len(frames) < count:
        ok, frame = capture.read()
        if not ok:
            capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            continue
        frames.append(cv2.resize(frame, size))
    capture.release()
    return frames


def print_table(title: str, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    print("  ".join(str(h).ljust(w) for h, w in zip(header, widths, strict=True)))
    for row in rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))
