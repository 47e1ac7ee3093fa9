"""`oricf bench models`: what the Open Inference Protocol costs, and which back end is faster.

On 640x480 frames of the pedestrian video, everything interleaved frame by frame in one run:

1. Latency of one detection (pre-processing, the network, decoding and NMS) for a declared
   model: in process; through ModelInfer on `oricf serve models` (a separate process on
   localhost) with the tensor sent raw, with the frame sent as JPEG for the server to
   pre-process, with the tensor in and the output back through system shared memory, and
   with raw UINT8 pixels or JPEG in and decoded detections back (bench/models_edge.py); and
   through the typed Detect of `oricf serve detector`, its frame on the wire or in shared
   memory; with `--triton`, the same ways through NVIDIA Triton Inference Server beside them
   (bench/models_triton.py; `scripts/triton-server.sh --install` installs it once). Goals:
   shared memory adds at most 1 ms median over in process; JPEG with decoded detections at
   most 2 ms. Beside them, a call that carries no tensor and runs no
   model (ModelMetadata): the floor that any call through a service pays.
2. The same model on onnxruntime and on OpenVINO (f32), each at 1 and 2 threads: median
   latency of the network alone, and how far the outputs differ from onnxruntime's. A back
   end whose package is not installed (OpenVINO: the `openvino` extra) is skipped, with a
   line saying how to add it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import grpc
import numpy as np
import yaml

from oricf.bench.common import JPEG_QUALITY, load_frames, median_ms, print_table, served
from oricf.bench.entry import missing
from oricf.bench.models_edge import edge_ways
from oricf.bench.models_triton import triton_ways, unusable
from oricf.config import config_dir
from oricf.gateway.endpoints import CHANNEL_OPTIONS  # as the gateway's calls are made
from oricf.imaging import decode_image, encode_image
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.models.declared import DeclaredModel
from oricf.models.heads import DetectionHead
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip_pb2
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.store import ModelStore
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc

# Outputs of two back ends agree when no element differs by more than this (FP32 networks
# reorder sums differently; class scores and box offsets are of order 1).
AGREEMENT = 1e-3
# Parts of the paths timed on their own, interleaved with them: a call to the same server
# that carries no tensor and runs no model (the part of every path through a service that is
# the call itself: gRPC, HTTP/2, the server's thread hand-off), and the JPEG path's
# encoding (client) and decoding (server) of the frame.
CALL_ALONE = "a call alone (ModelMetadata)"
CODEC_ALONE = "JPEG encode + decode alone"
# The back ends compared, each with the extra of oricf that installs it (None: a dependency).
ENGINES: dict[str, str | None] = {"onnxruntime": None, "openvino": "openvino"}


def timed(call: Callable[[], object]) -> float:
    started = time.perf_counter()
    call()
    return time.perf_counter() - started


def encoded(frame: np.ndarray) -> np.ndarray:
    tensor = np.empty(1, dtype=object)
    tensor[0] = encode_image(frame, "jpeg", JPEG_QUALITY)
    return tensor


def protocol_overhead(declaration: ModelDeclaration, path: Path, frames: list[np.ndarray],
                      folder: Path, triton: bool = False) -> dict[str, list[float]]:
    model = DeclaredModel(declaration, ModelStore())
    model.load()
    head = model.head
    assert isinstance(head, DetectionHead), "the protocol benchmark needs a detection model"
    score = head.task.min_score
    models_yaml = folder / "models.yaml"
    models_yaml.write_text(yaml.safe_dump({"models": [str(path)]}))
    detector_yaml = folder / "detector.yaml"
    detector_yaml.write_text(yaml.safe_dump({"model": str(path)}))
    latency: dict[str, list[float]] = {"in-process": [], "ModelInfer raw tensor": [],
                                       "ModelInfer jpeg": [], "Detect rgb8": []}
    with served("models", "--config", str(models_yaml)) as (models_address, _), \
            served("detector", "--config", str(detector_yaml)) as (detector_address, _):
        oip = oip_grpc.GRPCInferenceServiceStub(
            grpc.insecure_channel(models_address, options=CHANNEL_OPTIONS))
        typed = detector_pb2_grpc.DetectorStub(
            grpc.insecure_channel(detector_address, options=CHANNEL_OPTIONS))

        def in_process(frame: np.ndarray) -> object:
            return model.detect(model.prepare(frame), score)

        def over_oip(frame: np.ndarray) -> object:
            prepared = head.prepare(frame)
            response = oip.ModelInfer(infer_request(declaration.name, prepared.feeds),
                                      timeout=10)
            return head.decode(response_outputs(response), prepared, score)

        def over_oip_jpeg(frame: np.ndarray) -> object:
            prepared = head.prepare(frame)  # only its geometry is used: the server prepares
            response = oip.ModelInfer(infer_request(declaration.name,
                                                    {head.input_name: encoded(frame)}),
                                      timeout=10)
            return head.decode(response_outputs(response), prepared, score)

        def over_detect(frame: np.ndarray) -> object:
            image = common_pb2.Image(data=frame[:, :, ::-1].tobytes(), encoding="rgb8",
                                     width=frame.shape[1], height=frame.shape[0])
            return typed.Detect(detector_pb2.DetectRequest(image=image), timeout=10)

        ways = dict(zip(latency, (in_process, over_oip, over_oip_jpeg, over_detect),
                        strict=True))
        registry = oip_grpc.GRPCInferenceServiceStub(
            grpc.insecure_channel(detector_address, options=CHANNEL_OPTIONS))
        with edge_ways(declaration, head, oip, registry, typed) as more, \
                triton_ways(head, triton) as at_triton:
            more.update(at_triton)
            ways.update(more)
            latency.update({name: [] for name in more})
            for frame in frames[:10]:
                for way in ways.values():
                    way(frame)
            metadata = oip_pb2.ModelMetadataRequest(name=declaration.name)
            parts: dict[str, Callable[[np.ndarray], object]] = {
                CALL_ALONE: lambda _: oip.ModelMetadata(metadata, timeout=10),
                CODEC_ALONE: lambda f: decode_image(encoded(f)[0], "jpeg")}
            latency.update({name: [] for name in parts})
            timed_ways: dict[str, Callable[[np.ndarray], object]] = {**ways, **parts}
            for frame in frames:
                for name, measured in timed_ways.items():
                    latency[name].append(timed(lambda w=measured, f=frame: w(f)))  # type: ignore[misc]
    model.close()
    return latency


def installed_engines() -> list[str]:
    """The back ends whose package imports; a line for each one skipped."""
    engines = []
    for engine, extra in ENGINES.items():
        hint = missing(engine, extra)
        if hint is None:
            engines.append(engine)
        else:
            print(f"{engine}: not installed ({hint}); skipped", flush=True)
    return engines


def backends(declaration: ModelDeclaration, frames: list[np.ndarray], engines: list[str]
             ) -> tuple[dict[str, list[float]], dict[str, float]]:
    data = declaration.model_dump(mode="json", exclude_unset=True)
    loaded = {}
    for engine in engines:
        for threads in (1, 2):
            variant = {**data, "backend": {"engine": engine, "threads": threads}}
            model = DeclaredModel(ModelDeclaration.model_validate(variant), ModelStore())
            model.load()
            loaded[f"{engine} {threads} thread{'s' * (threads > 1)}"] = model
    reference = next(iter(loaded.values()))
    assert reference.head is not None
    feeds = [reference.head.prepare(frame).feeds for frame in frames]
    latency: dict[str, list[float]] = {name: [] for name in loaded}
    difference = dict.fromkeys(loaded, 0.0)
    for feed in feeds:
        expected = reference.infer(feed)
        for name, model in loaded.items():
            started = time.perf_counter()
            outputs = model.infer(feed)
            latency[name].append(time.perf_counter() - started)
            difference[name] = max(difference[name], *(
                float(np.abs(outputs[k] - expected[k]).max()) for k in expected))
    for model in loaded.values():
        model.close()
    return latency, difference


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oricf bench models", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=200, help="frames per measurement")
    parser.add_argument("--model", type=Path,
                        default=config_dir() / "models" / "yolox-nano.yaml",
                        help="a declared detection model")
    parser.add_argument("--triton", action="store_true",
                        help="the same ways through NVIDIA Triton Inference Server too "
                             "(scripts/triton-server.sh --install, once)")
    args = parser.parse_args(argv)
    declaration = load_declaration(args.model)
    why_not = unusable(declaration) if args.triton else None
    if why_not is not None:
        print(f"oricf bench models --triton: {why_not}", file=sys.stderr)
        return 2
    frames = load_frames(args.frames)
    with tempfile.TemporaryDirectory(prefix="oricf-bench-") as folder:
        latency = protocol_overhead(declaration, args.model.resolve(), frames, Path(folder),
                                    args.triton)
    call_alone, codec_alone = latency.pop(CALL_ALONE), latency.pop(CODEC_ALONE)
    base = median_ms(latency["in-process"])
    print_table(f"{declaration.name}: one detection per 640x480 frame "
                f"(median of {len(frames)}, interleaved)",
                ["path", "median ms", "added ms", "ratio"],
                [[name, f"{median_ms(v):.2f}", f"{median_ms(v) - base:+.2f}",
                  f"{median_ms(v) / base:.2f}x"] for name, v in latency.items()])
    added = median_ms(latency["ModelInfer raw tensor"]) - base
    print(f"\nModelInfer adds {added:.2f} ms median per frame over in process")
    shared = median_ms(latency["ModelInfer shm"]) - base
    print(f"ModelInfer over shared memory adds {shared:.2f} ms (goal <= 1 ms)")
    edge = median_ms(latency["ModelInfer jpeg, decoded"]) - base
    print(f"ModelInfer with JPEG in and decoded detections back adds {edge:.2f} ms "
          f"(goal <= 2 ms)")
    if "Triton shm" in latency:
        print(f"beside it, Triton: the tensor on the wire "
              f"{median_ms(latency['Triton raw tensor']) - base:+.2f} ms, in shared memory "
              f"{median_ms(latency['Triton shm']) - base:+.2f} ms, UINT8 pixels in and "
              f"decoded detections back "
              f"{median_ms(latency['Triton uint8, decoded']) - base:+.2f} ms")
    print(f"of which: a call that carries no tensor and runs no model takes "
          f"{median_ms(call_alone):.2f} ms (the floor of every path through a service); "
          f"encoding the frame as JPEG (q{JPEG_QUALITY}) and decoding it, "
          f"{median_ms(codec_alone):.2f} ms")

    print()
    timings, difference = backends(declaration, frames, installed_engines())
    first = median_ms(next(iter(timings.values())))
    print_table(f"{declaration.name}: the network alone, per back end "
                f"(median of {len(frames)}, interleaved)",
                ["back end", "median ms", "ratio", "max |difference| vs onnxruntime"],
                [[name, f"{median_ms(v):.2f}", f"{median_ms(v) / first:.2f}x",
                  f"{difference[name]:.1e}"] for name, v in timings.items()])
    worst = max(difference.values())
    print(f"\noutputs agree within {worst:.1e} (tolerance {AGREEMENT:.0e}): "
          f"{'yes' if worst <= AGREEMENT else 'NO'}")
    return 0 if worst <= AGREEMENT else 1
