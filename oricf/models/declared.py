"""A declared model, loaded: its session, its tensors, and its task's head.

The model class of the services that serve declared models (the detector, `oricf serve
models`): `load()`, `infer()`, `infer_batch()`, `close()`, `info()`; it knows nothing of
gRPC. Inputs and outputs may be renamed or reshaped by the declaration: callers use the
declared names, the session the file's own. A dimension declared free (-1) that the file
fixes is freed in the graph (onnxruntime); a freed batch must then give what its items give
alone, or the model is refused.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from oricf.errors import ConfigError, InvalidInput, NotReady
from oricf.models.backends import Session, open_session
from oricf.models.declaration import ModelDeclaration, TensorOverride
from oricf.models.heads import DetectionHead, Detections, Head, Prepared, make_head
from oricf.models.info import ModelInfo
from oricf.models.mlp_source import converted
from oricf.models.policy_shapes import check_policy
from oricf.models.policy_task import PolicyTask
from oricf.models.tensors import DATATYPES, TensorSpec, clip
from oricf.store import ModelStore, sha256_of

log = logging.getLogger(__name__)

# What detect() takes for one image: the prepared image, the minimum score, the class ids.
DetectArgs = tuple[Prepared, float, "np.ndarray | None"]
# A batch's outputs must match its items' alone to this tolerance (of the outputs' range):
# a freed batch dimension must not change the answers.
BATCH_TOLERANCE = 1e-4
# On an accelerator: a share of how far two different items' outputs are apart.
ACCELERATED_BATCH_TOLERANCE = 0.1


def _override(specs: list[TensorSpec], overrides: list[TensorOverride], where: str
              ) -> list[TensorSpec]:
    """The i-th override renames or reshapes the i-th tensor of the file."""
    if len(overrides) > len(specs):
        raise ConfigError(f"{where}: {len(overrides)} given, the model file has {len(specs)}")
    result = list(specs)
    for i, o in enumerate(overrides):
        spec = result[i]
        if o.datatype is not None and o.datatype != spec.datatype:
            raise ConfigError(f"{where}[{i}].datatype: the model file says {spec.datatype}")
        if o.shape is not None and len(o.shape) != len(spec.shape):
            raise ConfigError(f"{where}[{i}].shape: the model file has {len(spec.shape)} "
                              f"dimensions")
        result[i] = replace(spec, name=o.name,
                            shape=tuple(o.shape) if o.shape is not None else spec.shape)
    return result


@dataclass(frozen=True)
class FixedBatch:
    """Batches run at one size, padded: `size` rows, where `on` says (None: where the model
    runs on an accelerator). onnxruntime's CUDA provider plans cuDNN anew whenever the input
    shape differs from the last run's, seconds each time (1.3-3.6 s for YOLOX-Nano on an
    H200, against 9-12 ms for a batch of 16 at an unchanged shape; docs/platforms.md), so a
    batcher whose batches vary in size stalls on every change. Padded to one size, every
    run after the first reuses the plan: a few images' compute for no stall."""

    size: int
    on: bool | None = None


class DeclaredModel:
    def __init__(self, declaration: ModelDeclaration, store: ModelStore,
                 batched: bool = False, fixed_batch: FixedBatch | None = None) -> None:
        """batched: the service batches requests to it, so it must take a batch (checked at
        load); fixed_batch: how its batches run (FixedBatch)."""
        if declaration.weights is None:
            raise ConfigError(f"model {declaration.name}: weights: required to serve it")
        self.declaration = declaration
        self.name = declaration.name
        self._store = store
        self._session: Session | None = None
        self.inputs: list[TensorSpec] = []
        self.outputs: list[TensorSpec] = []
        self.head: Head | None = None
        self._file_names: dict[str, str] = {}  # declared input name -> the file's name
        self._output_names: dict[str, str] = {}  # the file's output name -> declared name
        self.sha256 = ""
        self.license = declaration.license
        self.batched = batched
        self.fixed_batch = fixed_batch
        self.pad_to = 0  # rows every batch runs at, padded (0: as they come)

    def weights_path(self) -> Path:
        weights = self.declaration.weights
        assert weights is not None
        if weights.catalog is not None:
            entry = self._store.entry(weights.catalog)
            path = self._store.path(weights.catalog, weights.file)
            self.sha256 = next(f.sha256 for f in entry.files if f.name == path.name)
            self.license = self.license or entry.license
            return self._converted(path, weights.catalog)
        assert weights.path is not None
        if not weights.path.is_file():
            raise ConfigError(f"model {self.name}: weights.path: no file {weights.path}")
        if weights.sha256 is not None or weights.convert is not None:
            self.sha256 = sha256_of(weights.path)
            if weights.sha256 is not None and self.sha256 != weights.sha256:
                raise ConfigError(f"model {self.name}: {weights.path} has sha256 "
                                  f"{self.sha256}, the declaration says {weights.sha256}")
        return self._converted(weights.path, str(weights.path))

    def _converted(self, path: Path, key: str) -> Path:
        """The model file itself, or the ONNX model made once from a weights file."""
        weights = self.declaration.weights
        if weights is None or weights.convert is None:
            return path
        return converted(path, self.sha256, key)

    def load(self) -> None:
        free = [tuple(axis for axis, d in enumerate(o.shape or ()) if d == -1)
                for o in self.declaration.inputs]
        session = open_session(self.weights_path(), self.declaration.backend, free)
        self.inputs = _override(session.inputs, self.declaration.inputs, "inputs")
        self.outputs = _override(session.outputs, self.declaration.outputs, "outputs")
        self._file_names = {d.name: f.name for d, f in zip(self.inputs, session.inputs,
                                                           strict=False)}
        self._output_names = {f.name: d.name for d, f in zip(self.outputs, session.outputs,
                                                             strict=False)}
        task = self.declaration.task
        if isinstance(task, PolicyTask):
            check_policy(self.declaration.source, task, self.inputs, self.outputs)
        elif task is not None:
            name = task.image.input or self.inputs[0].name
            if name not in {s.name for s in self.inputs}:
                raise ConfigError(f"model {self.name}: task.image.input: the model has no "
                                  f"input '{name}' (inputs: "
                                  f"{', '.join(s.name for s in self.inputs)})")
            spec = self.input(name)
            try:
                self.head = make_head(task, name, spec.shape)
            except ValueError as exc:
                raise ConfigError(f"model {self.name}: task: {exc}") from None
        self._session = session
        log_placement(self.name, session)
        self._warm_up()
        if any(0 in axes for axes in session.freed):
            check_batching(self)
        if self.batched and not self.batchable:
            fixed = ", ".join(f"'{spec.name}' {list(spec.shape)}" for spec in session.inputs)
            raise ConfigError(f"model {self.name}: batching: its inputs take no batch of any "
                              f"size ({fixed}); declare the batch dimension free (inputs: "
                              f"[{{name: ..., shape: [-1, ...]}}]) where the graph allows it")
        self._fix_batch()

    def _fix_batch(self) -> None:
        fixed = self.fixed_batch
        if fixed is None or not self.batchable or fixed.size < 2:
            return
        if not (fixed.on if fixed.on is not None else not self.on_cpu):
            return
        self.pad_to = fixed.size
        self.infer_batch([self._zeros()])  # the one shape, planned now rather than on a call
        log.info("model %s: every batch runs at %d rows, padded (batching.fixed_size; on %s "
                 "a new batch size is planned anew)", self.name, self.pad_to,
                 self.info().providers[0])

    @property
    def on_cpu(self) -> bool:
        return self.info().providers[:1] in (["CPUExecutionProvider"], ["CPU"])

    def _zeros(self) -> dict[str, np.ndarray]:
        """One item of zeros for every input (its free dimensions 1)."""
        return {spec.name: np.zeros([d if d > 0 else 1 for d in spec.shape],
                                    np.dtype(DATATYPES[spec.datatype].numpy))
                for spec in self.inputs}

    @property
    def batchable(self) -> bool:
        """Every input of the session takes a batch of any size (its first dimension)."""
        session = self._session
        return session is not None and bool(session.inputs) and all(
            spec.shape[:1] == (-1,) and spec.datatype != "BYTES" for spec in session.inputs)

    def _warm_up(self) -> None:
        if any(spec.datatype == "BYTES" for spec in self.inputs):
            return
        feeds = self._zeros()
        if self.head is None:
            self.infer(feeds)
            return
        prepared = self.head.prepare(np.zeros((64, 64, 3), np.uint8))
        try:  # a task that does not fit the model fails here, not on a request
            self.head.decode(self.infer({**feeds, **prepared.feeds}), prepared)
        except InvalidInput as exc:
            raise ConfigError(f"model {self.name}: task: {exc}") from None

    def close(self) -> None:
        self._session = None

    def info(self) -> ModelInfo:
        backend = self.declaration.backend
        session = self._session
        return ModelInfo(
            model=self.name, runtime=session.runtime if session else backend.engine,
            providers=session.devices if session else [], license=self.license,
            sha256=self.sha256, labels=self.head.labels if self.head else [],
            parameters={"threads": str(backend.threads),
                        "task": self.declaration.task.kind if self.declaration.task else ""})

    def input(self, name: str) -> TensorSpec:
        for spec in self.inputs:
            if spec.name == name:
                return spec
        raise InvalidInput(f"model {self.name} has no input '{clip(name)}' "
                           f"(inputs: {', '.join(s.name for s in self.inputs)})")

    def infer(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Runs the model on declared-name inputs, every one checked; declared-name outputs."""
        session = self._session
        if session is None:
            raise NotReady(f"model {self.name} is not loaded")
        for spec in self.inputs:
            if spec.name not in feeds:
                raise InvalidInput(f"model {self.name}: input '{spec.name}' is missing")
        renamed = {}
        for name, array in feeds.items():
            self.input(name).check(array)
            renamed[self._file_names[name]] = array
        results = session.run(renamed)
        return {self._output_names[name]: value for name, value in results.items()}

    def infer_batch(self, items: list[dict[str, np.ndarray]]) -> list[dict[str, np.ndarray]]:
        """One run for several requests' inputs, joined along the batch dimension (every
        item the same names and shapes but the first dimension); each item's outputs."""
        if len(items) == 1 and not self.pad_to:
            return [self.infer(items[0])]
        rows = [len(next(iter(feeds.values()))) for feeds in items]
        joined = {name: np.concatenate([feeds[name] for feeds in items])
                  for name in items[0]}
        total = sum(rows)
        if 0 < total < self.pad_to:  # copies of the first row: real, finite inputs
            joined = {name: np.concatenate([value, np.repeat(value[:1], self.pad_to - total,
                                                             axis=0)])
                      for name, value in joined.items()}
        outputs = self.infer(joined)
        if total < self.pad_to:
            outputs = {name: value[:total] if value.ndim and len(value) == self.pad_to
                       else value for name, value in outputs.items()}
        for name, value in outputs.items():
            if value.ndim == 0 or value.shape[0] != total:
                raise InvalidInput(f"model {self.name}: output '{name}' of shape "
                                   f"{list(value.shape)} does not follow the batch of {total}")
        bounds = np.cumsum(rows)[:-1]
        split = {name: np.split(value, bounds) for name, value in outputs.items()}
        return [{name: parts[i] for name, parts in split.items()} for i in range(len(items))]

    def detect_batch(self, frames: list[DetectArgs]) -> list[Detections | Exception]:
        """detect() for several prepared images in one network run; post-processing per
        image, so one image's error is its own."""
        head = self._detection_head()
        started = time.perf_counter()
        outputs = self.infer_batch([prepared.feeds for prepared, _, _ in frames])
        inference_ms = (time.perf_counter() - started) * 1e3
        results: list[Detections | Exception] = []
        for (prepared, min_score, class_ids), output in zip(frames, outputs, strict=True):
            try:
                result = head.decode(output, prepared, min_score, class_ids)
            except Exception as exc:
                results.append(exc)
                continue
            result.timings_ms.update(preprocess_ms=prepared.preprocess_ms,
                                     inference_ms=inference_ms)
            results.append(result)
        return results

    def prepare(self, pixels: np.ndarray) -> Prepared:
        return self._detection_head().prepare(pixels)

    def detect(self, prepared: Prepared, min_score: float,
               class_ids: np.ndarray | None = None) -> Detections:
        head = self._detection_head()
        started = time.perf_counter()
        outputs = self.infer(prepared.feeds)
        inference_ms = (time.perf_counter() - started) * 1e3
        result = head.decode(outputs, prepared, min_score, class_ids)
        result.timings_ms.update(preprocess_ms=prepared.preprocess_ms, inference_ms=inference_ms)
        return result

    def _detection_head(self) -> DetectionHead:
        if not isinstance(self.head, DetectionHead):
            raise ConfigError(f"model {self.name} is not a declared detection model "
                              f"(task.kind: detection)")
        return self.head



def log_placement(name: str, session: Session) -> None:
    """One line naming where the model runs, and the declared providers passed over."""
    passed = f" (passed over: {'; '.join(session.skipped)})" if session.skipped else ""
    log.info("model %s runs on %s with %s%s", name, session.devices[0], session.runtime, passed)


def check_batching(model: DeclaredModel) -> None:
    """Refuses a model whose freed batch dimension changes its answers: two different inputs
    run as one batch must give what each gives alone."""
    rng = np.random.default_rng(0)
    items = []
    for _ in range(2):
        feeds = {}
        for spec in model.inputs:
            shape = [1] + [d if d > 0 else 32 for d in spec.shape[1:]]
            dtype = np.dtype(DATATYPES[spec.datatype].numpy)
            feeds[spec.name] = (rng.uniform(0, 255, shape) if dtype.kind == "f"
                                else rng.integers(0, 2, shape)).astype(dtype)
        if model.head is not None:  # the image input as the task prepares it
            noise = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
            feeds.update(model.head.prepare(noise).feeds)
        items.append(feeds)
    try:
        batched = model.infer_batch(items)
    except Exception as exc:
        raise ConfigError(f"model {model.name}: inputs declare a free batch dimension, but "
                          f"the graph does not run a batch of 2: {exc}") from None
    on_cpu = model.on_cpu
    alone = [model.infer(feeds) for feeds in items]
    for name in alone[0]:
        apart = max(float(np.abs(alone[0][name] - alone[1][name]).max()), 1e-12)
        # On the CPU a batch gives its items' answers to rounding. On an accelerator a batch
        # takes other kernels (cuDNN's choice, TF32 sums), so it is held to a small share of
        # how far two different items' answers are apart: mixed items would be that far.
        for i in range(2):
            scale = max(float(np.abs(alone[i][name]).max()), 1.0)
            allowed = BATCH_TOLERANCE * scale if on_cpu else ACCELERATED_BATCH_TOLERANCE * apart
            worst = float(np.abs(batched[i][name] - alone[i][name]).max())
            if worst > allowed:
                raise ConfigError(
                    f"model {model.name}: inputs declare a free batch dimension, but the graph "
                    f"does not batch (output '{name}' of a batch differs from that of its "
                    f"items run alone by {worst:.3g}, two items differ by {apart:.3g}); "
                    f"declare the batch dimension as 1")
    log.info("model %s: batch dimension freed; a batch gives what its items give alone",
             model.name)
