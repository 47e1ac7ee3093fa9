"""`oricf bench providers`: one declared model on each execution provider, side by side.

The detector's model (the YAML's `model:`, YOLOX-Nano by default) is opened once per
provider setup and run on 640x480 frames of the pedestrian video, the setups interleaved
frame by frame in one run:

- `cpu`: CPUExecutionProvider with the YAML's threads (1, as the shipped services run);
- `cpu-all`: CPUExecutionProvider with every core of this machine;
- each provider named with --provider (CUDAExecutionProvider by default; Tensorrt...), with
  the CPU as its fallback.

Per setup and batch size: the provider that actually ran (a provider that cannot start here
falls back, and the table says so), median and p90 inference latency, frames per second,
and the ratio to `cpu`; and whether the people counts agree with `cpu` on every frame.

    oricf bench providers                                   # CUDA against the CPU
    oricf bench providers --provider TensorrtExecutionProvider --provider CUDAExecutionProvider
    oricf bench providers --batch 1,8,32 --frames 300
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from oricf.bench.common import load_frames, median_ms, print_table
from oricf.config import load_config, shipped_service_config
from oricf.models.declaration import DetectionTask, OnnxRuntimeBackend, load_declaration
from oricf.models.declared import DeclaredModel, DetectArgs
from oricf.services.detector.service import DetectorConfig
from oricf.stats import p90
from oricf.store import ModelStore

PERSON = np.array([0])


@dataclass
class Setup:
    label: str
    model: DeclaredModel
    seconds: dict[int, list[float]] = field(default_factory=dict)
    counts: list[int] = field(default_factory=list)

    @property
    def running(self) -> str:
        return self.model.info().providers[0]


def open_setup(label: str, config: DetectorConfig, providers: list[str],
               threads: int) -> Setup:
    declaration = load_declaration(config.model)
    backend = declaration.backend
    if not isinstance(backend, OnnxRuntimeBackend):
        raise SystemExit(f"{config.model}: backend.engine must be onnxruntime to compare "
                         "its execution providers")
    declaration = declaration.model_copy(update={"backend": backend.model_copy(
        update={"providers": providers, "threads": threads})})
    model = DeclaredModel(declaration, ModelStore(), batched=True)
    model.load()
    return Setup(label, model)


def run_batch(setup: Setup, frames: list[np.ndarray], min_score: float) -> list[int]:
    """One inference over the frames as a batch; the people counted in each."""
    model = setup.model
    prepared: list[DetectArgs] = [(model.prepare(f), min_score, PERSON) for f in frames]
    started = time.perf_counter()
    results = model.detect_batch(prepared) if len(frames) > 1 else [
        model.detect(*prepared[0])]
    setup.seconds.setdefault(len(frames), []).append(time.perf_counter() - started)
    counts = []
    for result in results:
        if isinstance(result, Exception):
            raise result
        counts.append(len(result.boxes))
    return counts


def measure(setups: list[Setup], frames: list[np.ndarray], batches: list[int],
            min_score: float) -> None:
    for size in batches:
        for start in range(0, len(frames) - size + 1, size):
            chunk = frames[start:start + size]
            for setup in setups:  # interleaved: the machine's drift hits every setup alike
                counts = run_batch(setup, chunk, min_score)
                if size == 1:
                    setup.counts.extend(counts)


def report(setups: list[Setup], batches: list[int]) -> None:
    base = setups[0]
    rows = []
    for setup in setups:
        agree = sum(a == b for a, b in zip(setup.counts, base.counts, strict=True))
        for size in batches:
            seconds = setup.seconds[size]
            ratio = median_ms(base.seconds[size]) / median_ms(seconds)
            rows.append((setup.label, setup.running, size, f"{median_ms(seconds):.2f}",
                         f"{p90(seconds) * 1e3:.2f}", f"{size / np.median(seconds):.0f}",
                         f"{ratio:.1f}x", f"{agree}/{len(base.counts)}"))
    print_table("inference per batch (pre- and post-processing included), medians",
                ("setup", "ran on", "batch", "ms", "p90 ms", "frames/s", "vs cpu",
                 "counts agree"), rows)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="oricf bench providers", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, default=shipped_service_config("detector"),
                        help="detector YAML whose model is measured")
    parser.add_argument("--provider", action="append",
                        help="an accelerated setup (repeatable; default "
                             "CUDAExecutionProvider), each with the CPU as fallback")
    parser.add_argument("--frames", type=int, default=200, help="frames per batch size")
    parser.add_argument("--batch", default="1,8", help="batch sizes, comma-separated")
    parser.add_argument("--cpu-threads", type=int, default=os.cpu_count() or 1,
                        help="threads of the cpu-all setup")
    return parser.parse_args(argv)


def main(argv: Sequence[str]) -> int:
    args = parse_args(argv)
    config = load_config(args.config, DetectorConfig)
    batches = [int(b) for b in args.batch.split(",")]
    yaml_threads = load_declaration(config.model).backend.threads
    cpu = ["CPUExecutionProvider"]
    setups = [open_setup("cpu", config, cpu, yaml_threads),
              open_setup(f"cpu-all x{args.cpu_threads}", config, cpu, args.cpu_threads)]
    for provider in args.provider or ["CUDAExecutionProvider"]:
        setups.append(open_setup(provider.removesuffix("ExecutionProvider").lower(), config,
                                 [provider, *cpu], yaml_threads))
    task = setups[0].model.declaration.task
    assert isinstance(task, DetectionTask)
    min_score = config.detection.min_score or task.min_score
    frames = load_frames(args.frames)
    print(f"{len(frames)} frames, batches {batches}: "
          + ", ".join(f"{s.label} on {s.running}" for s in setups), flush=True)
    measure(setups, frames[:max(batches)] * 2, batches, min_score)  # warm-up, not kept
    for setup in setups:
        setup.seconds.clear()
        setup.counts.clear()
    measure(setups, frames, batches, min_score)
    report(setups, batches)
    return 0
