"""The detector: `oricf serve detector`, oricf.v1.Detector for any declared detection model.

It returns detections only: counting, renaming labels and drawing boxes are the gateway's
post-processing steps, so each result has one owner whichever method produced it. Images
are decoded within the service's memory budget (`server.max_inflight_mb`), from the request
or from a shared-memory region a client on this host registered.
"""

from __future__ import annotations

import contextvars
import logging
import math
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import TypeAlias

import numpy as np
from pydantic import Field

from oricf.config import FilePath, Schema, config_dir
from oricf.errors import ConfigError, InvalidInput
from oricf.imaging import MAX_PIXELS, Detection, decode_image, decoded_bytes, image_size
from oricf.models.declaration import DetectionTask, load_declaration
from oricf.models.declared import DeclaredModel, DetectArgs, FixedBatch
from oricf.models.heads import Detections, Prepared
from oricf.models.info import ModelInfo
from oricf.models.shared_memory import SharedMemoryRef, check_region_name
from oricf.services.detector.labels import LabelSpace
from oricf.services.runtime import Call, Service, ServiceConfig
from oricf.services.runtime.batch_calls import run_batched
from oricf.services.runtime.batching import BatchingSettings
from oricf.services.runtime.errors import MESSAGE_REFUSALS, check_deadline, refusal
from oricf.services.runtime.shared_memory import SharedMemoryRegistry, SharedMemorySettings
from oricf.services.runtime.streams import hand_over
from oricf.services.runtime.tracing import spans_ending_now
from oricf.store import ModelStore
from oricf.tracing import span
from oricf.v1 import detector_pb2

log = logging.getLogger(__name__)
PREFETCH = 2  # frames of a stream prepared ahead of the one in the network


class DetectionSettings(Schema):
    min_score: float | None = Field(
        None, gt=0, le=1, description="default minimum score (default: the model's own)")
    labels: list[str] = Field(
        default_factory=list, description="labels kept when a request names none (empty: all)")


class ImageSettings(Schema):
    max_pixels: int = Field(MAX_PIXELS, ge=1, description="refuse larger images")


class DetectorConfig(ServiceConfig):
    """configs/services/detector.yaml: the server, which declared model, its default filter."""

    model: FilePath = Field(default_factory=lambda: config_dir() / "models" / "yolox-nano.yaml",
                            description="a declared detection model (configs/models/*.yaml)")
    detection: DetectionSettings = DetectionSettings()
    images: ImageSettings = ImageSettings()
    batching: BatchingSettings | None = Field(
        None, description="dynamic batching: requests of different callers share one "
                          "inference (off if absent; the model's batch dimension must be free)")
    shared_memory: SharedMemorySettings = Field(
        default_factory=SharedMemorySettings,
        description="images in system shared memory from clients on this host")


@dataclass(frozen=True)
class Frame:
    """A request checked, decoded and letterboxed: ready for the network."""

    frame_id: int
    width: int
    height: int
    prepared: Prepared
    class_ids: np.ndarray | None
    min_score: float
    started: float
    decode_ms: float


# What the stream reader hands over: a frame to run, a refusal, an error that ends the call,
# or None at the end of the stream.
StreamItem: TypeAlias = Frame | detector_pb2.DetectResponse | BaseException | None


class Detector(Service[DetectorConfig]):
    name = "detector"
    proto = detector_pb2.DESCRIPTOR.services_by_name["Detector"]
    config_schema = DetectorConfig

    def __init__(self, config: DetectorConfig, store: ModelStore) -> None:
        super().__init__(config, store)
        declaration = load_declaration(config.model)
        task = declaration.task
        if not isinstance(task, DetectionTask):
            raise ConfigError(f"{config.model}: task.kind: the detector serves detection models")
        batching = config.batching
        fixed = (None if batching is None
                 else FixedBatch(batching.max_batch_size, batching.fixed_size))
        self.model = DeclaredModel(declaration, store, batched=batching is not None,
                                   fixed_batch=fixed)
        self.labels = LabelSpace(task.label_list(), config.detection.labels)
        self.default_min_score = config.detection.min_score or task.min_score
        # The model object itself, loaded or not: the batcher drains before it closes.
        self.batcher = (None if batching is None
                        else self.batched(batching, self.model.detect_batch))
        if config.shared_memory.enabled:  # clients register the regions that requests name
            self.shared_memory = SharedMemoryRegistry(config.shared_memory)

    def load(self) -> None:
        self.model.load()

    def close(self) -> None:
        self.model.close()

    def info(self) -> ModelInfo:
        return replace(self.model.info(), labels=self.labels.labels)

    def detect(self, request: detector_pb2.DetectRequest,
               call: Call | None = None) -> detector_pb2.DetectResponse:
        frame = self.prepare(request)
        if call is not None:
            # Decoding may have taken the caller's whole deadline: no one waits for the rest.
            check_deadline(call, "before inference could start")
        return self.respond(frame, call)

    def detect_stream(self, requests: Iterator[detector_pb2.DetectRequest],
                      call: Call) -> Iterator[detector_pb2.DetectResponse]:
        # A reader thread takes frames off the wire and prepares them while the previous
        # frame is in the network; at most PREFETCH prepared frames wait, so a slow model
        # pushes back on the client (gRPC flow control) instead of queueing without bound.
        ready: queue.Queue[StreamItem] = queue.Queue(maxsize=PREFETCH)
        done = threading.Event()
        # In the call's context: the frames' decode spans are children of the call's span.
        reader = threading.Thread(target=contextvars.copy_context().run,
                                  args=(self._read_stream, requests, ready, done),
                                  name="detect-stream-reader", daemon=True)
        reader.start()
        try:
            while (item := ready.get()) is not None:
                if isinstance(item, BaseException):
                    raise item
                yield item if isinstance(item, detector_pb2.DetectResponse) \
                    else self.respond(item, call, cancel=False)
        finally:
            done.set()  # the call is over: the reader must not wait for room in the queue

    def _read_stream(self, requests: Iterator[detector_pb2.DetectRequest],
                     ready: queue.Queue[StreamItem], done: threading.Event) -> None:
        def put(item: StreamItem) -> bool:
            return hand_over(ready, item, done)

        try:
            for request in requests:
                if not put(self._prepare_or_refuse(request)):
                    return
        except Exception as exc:  # the stream broke or the model is not ready: end the call
            put(exc)
        put(None)

    def _prepare_or_refuse(self, request: detector_pb2.DetectRequest
                           ) -> Frame | detector_pb2.DetectResponse:
        try:
            return self.prepare(request)
        except MESSAGE_REFUSALS as exc:  # one bad frame must not end the stream
            error = refusal(exc)
            log.debug("frame %d refused: %s", request.frame_id, error.message)
            return detector_pb2.DetectResponse(frame_id=request.frame_id, error=error)

    def prepare(self, request: detector_pb2.DetectRequest) -> Frame:
        """Everything before the network: checks, image decoding, letterboxing. The decoded
        image is held in the memory budget until it is letterboxed (a frame keeps only the
        network's input)."""
        started = time.perf_counter()
        min_score = self._min_score(request.min_score)
        class_ids = self.labels.resolve(request.labels)
        image = request.image
        region = request.image_region if request.HasField("image_region") else None
        if region is not None and image.data:
            raise InvalidInput("image.data and image_region are both set")
        # The region's bytes are read within the budget: a copy, as large as it says.
        with self.budget.hold(region.byte_size if region else 0, "the image's region"):
            data = self._region_bytes(region) if region else image.data
            args = (data, image.encoding, image.width, image.height,
                    self.config.images.max_pixels)
            width, height = image_size(*args)
            with self.budget.hold(decoded_bytes(width, height), f"a {width}x{height} image"):
                with span("decode"):
                    pixels = decode_image(*args)
                decode_ms = (time.perf_counter() - started) * 1e3
                with span("preprocess"):
                    prepared = self.model.prepare(pixels)
        return Frame(request.frame_id, width, height, prepared, class_ids, min_score, started,
                     decode_ms)

    def _region_bytes(self, region: detector_pb2.SharedMemoryRef) -> bytes:
        if self.shared_memory is None:
            raise InvalidInput("image_region: shared memory is off on this server "
                               "(shared_memory.enabled)")
        ref = SharedMemoryRef(check_region_name(region.region), region.offset,
                              region.byte_size)
        return self.shared_memory.read(ref)

    def respond(self, frame: Frame, call: Call | None = None,
                cancel: bool = True) -> detector_pb2.DetectResponse:
        """The network (alone or in a batch), decoding its output, and the response."""
        raw = self._detections(frame, call, cancel)
        spans_ending_now([("inference", raw.timings_ms["inference_ms"]),
                          ("postprocess", raw.timings_ms["postprocess_ms"])])
        response = detector_pb2.DetectResponse(
            detections=[_detection_pb(d) for d in self.labels.detections(raw)],
            frame_id=frame.frame_id,
            image_width=frame.width,
            image_height=frame.height,
        )
        timings = response.timings
        timings.decode_ms = frame.decode_ms
        timings.preprocess_ms = raw.timings_ms["preprocess_ms"]
        timings.inference_ms = raw.timings_ms["inference_ms"]
        timings.postprocess_ms = raw.timings_ms["postprocess_ms"]
        timings.total_ms = (time.perf_counter() - frame.started) * 1e3
        return response

    def _detections(self, frame: Frame, call: Call | None, cancel: bool) -> Detections:
        args: DetectArgs = (frame.prepared, frame.min_score, frame.class_ids)
        if self.batcher is None:
            return self.model.detect(*args)
        return run_batched(self.batcher, args, call, cancel)

    def _min_score(self, requested: float) -> float:
        if requested == 0:
            return self.default_min_score
        if math.isnan(requested) or not 0 < requested <= 1:
            raise InvalidInput(f"min_score {requested} is out of range: use (0, 1], or 0 for the "
                               f"service default ({self.default_min_score})")
        return requested


def _detection_pb(detection: Detection) -> detector_pb2.Detection:
    box = detection.box
    return detector_pb2.Detection(
        label=detection.label, class_id=detection.class_id, score=detection.score,
        box=detector_pb2.BoundingBox(x_min=box.x_min, y_min=box.y_min, x_max=box.x_max,
                                     y_max=box.y_max))


SERVICE = Detector
