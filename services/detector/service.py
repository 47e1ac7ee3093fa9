"""The detector as a runtime service: `oricf serve detector`."""

from __future__ import annotations

import grpc

from oricf.services.detector.coco import COCO_LABELS
from oricf.services.detector.config import DetectorConfig
from oricf.services.detector.labels import LabelSpace
from oricf.services.detector.servicer import DetectorServicer
from oricf.services.detector.yolox import YoloxDetector, YoloxSettings
from oricf.services.runtime import ModelSlot, ServiceSpec
from oricf.store import ModelStore
from oricf.v1 import detector_pb2, detector_pb2_grpc


def create_model(config: DetectorConfig, store: ModelStore) -> YoloxDetector:
    name = config.model.name
    entry = store.entry(name)
    path = store.path(name, "model.onnx")
    return YoloxDetector(YoloxSettings(
        path=path, catalog_name=name, sha256=entry.files[0].sha256, license=entry.license,
        providers=tuple(config.model.providers), threads=config.model.threads,
        spin=config.model.spin,
        input_size=config.model.input_size, nms_iou=config.detection.nms_iou,
        max_detections=config.detection.max_detections))


def add_servicer(server: grpc.Server, slot: ModelSlot[YoloxDetector],
                 config: DetectorConfig) -> None:
    detection = config.detection
    labels = LabelSpace(COCO_LABELS, detection.label_map, detection.labels)
    detector_pb2_grpc.add_DetectorServicer_to_server(
        DetectorServicer(slot, config, labels), server)


SPEC = ServiceSpec(
    name="detector",
    service_name=detector_pb2.DESCRIPTOR.services_by_name["Detector"].full_name,
    config_schema=DetectorConfig,
    create_model=create_model,
    add_servicer=add_servicer,
)
