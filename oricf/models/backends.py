"""Inference back ends: a model file in, a session that runs named tensors out.

Each back end is one small class behind the same `Session` surface; BACKENDS maps the
`backend.engine` of a declaration to it. The engines are imported when a model opens, so
a missing one is refused at start with what to install, never at import time.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from oricf.errors import ConfigError
from oricf.models.declaration import Backend, OnnxRuntimeBackend, OpenVinoBackend
from oricf.models.providers import open_in_order
from oricf.models.tensors import TensorSpec, by_backend_name


class Session(Protocol):
    inputs: list[TensorSpec]
    outputs: list[TensorSpec]
    runtime: str                 # "onnxruntime 1.23.2"
    devices: list[str]           # execution providers or devices in use, the first runs
    skipped: list[str]           # declared ones passed over, each with why
    freed: list[tuple[int, ...]]  # per input, the axes the file fixed and this session frees

    def run(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]: ...


def _dims(shape: Any) -> tuple[int, ...]:
    return tuple(d if isinstance(d, int) and d >= 0 else -1 for d in shape)


class OnnxRuntimeSession:
    def __init__(self, path: Path, settings: OnnxRuntimeBackend,
                 free: Sequence[Sequence[int]] = ()) -> None:
        try:
            import onnxruntime as ort
        except ImportError:
            raise ConfigError("backend.engine onnxruntime: the onnxruntime package is not "
                              "installed") from None
        options = ort.SessionOptions()
        options.intra_op_num_threads = settings.threads
        options.inter_op_num_threads = 1
        # Spinning threads keep a core busy between frames: battery for a little latency.
        options.add_session_config_entry("session.intra_op.allow_spinning",
                                         "1" if settings.spin else "0")
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self._session, self.skipped = open_in_order(ort, str(path), options, settings)
        # Axes declared free (-1) that the file fixes: freed in the graph.
        self.freed = [tuple(a for a in axes if a < len(i.shape) and _dims(i.shape)[a] > 0)
                      for i, axes in zip(self._session.get_inputs(), free, strict=False)]
        if any(self.freed):
            from oricf.models.free_dims import free_dimensions

            self._session, self.skipped = open_in_order(
                ort, free_dimensions(path, self.freed), options, settings)
        self.inputs = [TensorSpec(i.name, by_backend_name("onnx", i.type).name, _dims(i.shape))
                       for i in self._session.get_inputs()]
        self.outputs = [TensorSpec(o.name, by_backend_name("onnx", o.type).name, _dims(o.shape))
                        for o in self._session.get_outputs()]
        self.runtime = f"onnxruntime {ort.__version__}"
        self.devices = list(self._session.get_providers())
        self._names = [o.name for o in self.outputs]

    def run(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        values = self._session.run(self._names, feeds)
        return dict(zip(self._names, values, strict=True))


class OpenVinoSession:
    def __init__(self, path: Path, settings: OpenVinoBackend,
                 free: Sequence[Sequence[int]] = ()) -> None:
        self.freed: list[tuple[int, ...]] = []  # OpenVINO runs the file's own dimensions
        try:
            import openvino as ov
        except ImportError:
            raise ConfigError("backend.engine openvino: the openvino package is not installed "
                              "(pip install 'oricf[openvino]')") from None
        core = ov.Core()
        if settings.device not in core.available_devices and settings.device != "AUTO":
            raise ConfigError(f"backend.device: {settings.device} is not available (available: "
                              f"{', '.join(core.available_devices)})")
        config: dict[str, Any] = {"INFERENCE_PRECISION_HINT": settings.precision}
        if settings.device == "CPU":
            # As onnxruntime runs concurrent calls side by side: `streams` inferences at once,
            # each with `threads` threads (OpenVINO counts the threads of all streams).
            config.update(NUM_STREAMS=settings.streams,
                          INFERENCE_NUM_THREADS=settings.threads * settings.streams)
        self._compiled = core.compile_model(str(path), settings.device, config)
        self.inputs = [self._spec(port) for port in self._compiled.inputs]
        self.outputs = [self._spec(port) for port in self._compiled.outputs]
        self.runtime = f"openvino {ov.__version__}"
        self.devices = [settings.device]
        self.skipped: list[str] = []
        # An infer request serves one call at a time: one per calling thread, and at most
        # `streams` inferences running (the others wait here, not inside OpenVINO).
        self._requests = threading.local()
        self._running = threading.BoundedSemaphore(settings.streams)

    @staticmethod
    def _spec(port: Any) -> TensorSpec:
        shape = tuple(d.get_length() if d.is_static else -1 for d in port.get_partial_shape())
        datatype = by_backend_name("openvino", port.get_element_type().get_type_name())
        return TensorSpec(port.get_any_name(), datatype.name, shape)

    def run(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        request = getattr(self._requests, "request", None)
        if request is None:
            request = self._requests.request = self._compiled.create_infer_request()
        with self._running:
            results = request.infer(feeds)
            return {spec.name: np.array(results[port], copy=True)
                    for spec, port in zip(self.outputs, self._compiled.outputs, strict=True)}


BACKENDS: dict[str, Callable[[Path, Any, Sequence[Sequence[int]]], Session]] = {
    "onnxruntime": OnnxRuntimeSession,
    "openvino": OpenVinoSession,
}


def open_session(path: Path, backend: Backend, free: Sequence[Sequence[int]] = ()) -> Session:
    """A session of the model file; free[i]: axes of its i-th input to free where the file
    fixes them (onnxruntime only; the caller checks that the graph still runs right)."""
    return BACKENDS[backend.engine](path, backend, free)
