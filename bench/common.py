"""Shared benchmark machinery: a real service process, timing loops, and result tables.

Benchmarks measure the things they compare side by side in one run, interleaved round by
round, because the machines they run on are shared and noisy; they report medians.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from oricf.config import deep_merge, read_yaml, shipped_service_config
from oricf.gateway.endpoints.config import ImageTransport
from oricf.launch.health import free_port, wait_serving
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.store import ModelStore

FRAME_SIZE = (640, 480)
# The quality the gateway encodes frames for a link with (`image.jpeg_quality`'s default).
JPEG_QUALITY: int = ImageTransport.model_fields["jpeg_quality"].default


def median_ms(seconds: Sequence[float]) -> float:
    return statistics.median(seconds) * 1e3


@contextmanager
def served(service: str, *args: str) -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    """`oricf serve SERVICE` in a child process on a free local port, stopped on exit."""
    address = f"127.0.0.1:{free_port()}"
    command = [sys.executable, "-m", "oricf", "--log-level", "WARNING", "serve", service,
               "--listen", address, *args]
    process = subprocess.Popen(command, env=os.environ.copy())
    try:
        wait_serving(address, process=process)
        yield address, process
    finally:
        stop(process)


def stop(process: subprocess.Popen[Any], timeout: float = 30) -> None:
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


def variant_config(service: str, overrides: dict[str, Any], folder: Path, tag: str) -> Path:
    """The shipped service YAML with overrides, written into folder for `oricf serve --config`
    (a variant measured beside the shipped config)."""
    data = deep_merge(read_yaml(shipped_service_config(service)), overrides)
    path = folder / f"{service}-{tag}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def shipped_detector_model() -> ModelDeclaration:
    """The model the shipped detector YAML declares."""
    path = shipped_service_config("detector")
    return load_declaration(path.parent / read_yaml(path)["model"])


def detector_with_threads(threads: int, folder: Path) -> Path:
    """The shipped detector YAML with its declared model at another thread count, written
    into folder for `oricf serve detector --config`."""
    declaration = shipped_detector_model().model_dump(mode="json", exclude_unset=True)
    declaration["backend"]["threads"] = threads
    model = folder / f"model-{threads}-threads.yaml"
    model.write_text(yaml.safe_dump(declaration))
    return variant_config("detector", {"model": str(model)}, folder, f"{threads}-threads")


def print_table(title: str, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    print("  ".join(str(h).ljust(w) for h, w in zip(header, widths, strict=True)))
    for row in rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))
