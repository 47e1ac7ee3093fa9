"""oricf.v1.Detector: turns requests into domain values, calls the model, and back.

It returns detections only: counting, renaming labels and drawing boxes are the gateway's
post-processing steps, so each result has one owner whichever method produced it."""

from __future__ import annotations

import contextvars
import logging
import math
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TypeAlias

import grpc
import numpy as np

from oricf.errors import InvalidInput, Overloaded
from oricf.imaging import Detection, decode_image, decoded_bytes, image_size
from oricf.models.declared import DeclaredModel, DetectArgs
from oricf.models.heads import Detections, Prepared
from oricf.models.shared_memory import SharedMemoryRef, check_region_name
from oricf.services.detector.config import DetectorConfig
from oricf.services.detector.labels import LabelSpace
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.batch_calls import run_batched
from oricf.services.runtime.batching import Batcher
from oricf.services.runtime.errors import check_deadline, status_for
from oricf.services.runtime.info import model_info_response
from oricf.services.runtime.limits import MemoryBudget
from oricf.services.runtime.shared_memory import SharedMemoryRegistry
from oricf.services.runtime.tracing import spans_ending_now
from oricf.tracing import span
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc

log = logging.getLogger(__name__)
PREFETCH = 2  # frames of a stream prepared ahead of the one in the network


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


class DetectorServicer(detector_pb2_grpc.DetectorServicer):
    def __init__(self, slot: ModelSlot[DeclaredModel], config: DetectorConfig,
                 labels: LabelSpace, default_min_score: float,
                 batcher: Batcher[DetectArgs, Detections] | None = None,
                 shared_memory: SharedMemoryRegistry | None = None) -> None:
        self.slot = slot
        self.shared_memory = shared_memory
        self.config = config
        self.labels = labels
        self.default_min_score = default_min_score
        self.batcher = batcher
        self.budget = MemoryBudget(config.server.max_inflight_bytes,
                                   config.server.retry_after_ms)

    def Detect(self, request: detector_pb2.DetectRequest,
               context: grpc.ServicerContext) -> detector_pb2.DetectResponse:
        return self.detect(request, context)

    def DetectStream(self, request_iterator: Iterator[detector_pb2.DetectRequest],
                     context: grpc.ServicerContext) -> Iterator[detector_pb2.DetectResponse]:
        # A reader thread takes frames off the wire and prepares them while the previous
        # frame is in the network; at most PREFETCH prepared frames wait, so a slow model
        # pushes back on the client (gRPC flow control) instead of queueing without bound.
        ready: queue.Queue[StreamItem] = queue.Queue(maxsize=PREFETCH)
        done = threading.Event()
        # In the call's context: the frames' decode spans are children of the call's span.
        reader = threading.Thread(target=contextvars.copy_context().run,
                                  args=(self._read_stream, request_iterator, ready, done),
                                  name="detect-stream-reader", daemon=True)
        reader.start()
        try:
            while (item := ready.get()) is not None:
                if isinstance(item, BaseException):
                    raise item
                yield item if isinstance(item, detector_pb2.DetectResponse) \
                    else self.respond(item, context, cancel=False)
        finally:
            done.set()  # the call is over: the reader must not wait for room in the queue

    def _read_stream(self, requests: Iterator[detector_pb2.DetectRequest],
                     ready: queue.Queue[StreamItem], done: threading.Event) -> None:
        def put(item: StreamItem) -> bool:
            while not done.is_set():
                try:
                    ready.put(item, timeout=0.1)
                    return True
                except queue.Full:
                    continue
            return False

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
        except (InvalidInput, Overloaded) as exc:  # one bad frame must not end the stream
            code, message = status_for(exc)
            log.debug("frame %d refused: %s", request.frame_id, message)
            return detector_pb2.DetectResponse(
                frame_id=request.frame_id,
                error=common_pb2.Error(code=code.value[0], message=message))

    def GetModelInfo(self, request: common_pb2.GetModelInfoRequest,
                     context: grpc.ServicerContext) -> common_pb2.GetModelInfoResponse:
        response = model_info_response("detector", self.slot)
        response.labels[:] = self.labels.labels
        return response

    def detect(self, request: detector_pb2.DetectRequest,
               context: grpc.ServicerContext | None = None) -> detector_pb2.DetectResponse:
        frame = self.prepare(request)
        if context is not None:
            # Decoding may have taken the caller's whole deadline: no one waits for the rest.
            check_deadline(context, "before inference could start")
        return self.respond(frame, context)

    def prepare(self, request: detector_pb2.DetectRequest) -> Frame:
        """Everything before the network: checks, image decoding, letterboxing. The decoded
        image is held in the memory budget until it is letterboxed (a frame keeps only the
        network's input)."""
        started = time.perf_counter()
        model = self.slot.get()
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
                    prepared = model.prepare(pixels)
        return Frame(request.frame_id, width, height, prepared, class_ids, min_score, started,
                     decode_ms)

    def _region_bytes(self, region: detector_pb2.SharedMemoryRef) -> bytes:
        if self.shared_memory is None:
            raise InvalidInput("image_region: shared memory is off on this server "
                               "(shared_memory.enabled)")
        ref = SharedMemoryRef(check_region_name(region.region), region.offset,
                              region.byte_size)
        return self.shared_memory.read(ref)

    def respond(self, frame: Frame, context: grpc.ServicerContext | None = None,
                cancel: bool = True) -> detector_pb2.DetectResponse:
        """The network (alone or in a batch), decoding its output, and the response."""
        raw = self._detections(frame, context, cancel)
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

    def _detections(self, frame: Frame, context: grpc.ServicerContext | None,
                    cancel: bool) -> Detections:
        args: DetectArgs = (frame.prepared, frame.min_score, frame.class_ids)
        model = self.slot.get()
        if self.batcher is None:
            return model.detect(*args)
        return run_batched(self.batcher, args, context, cancel)

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
