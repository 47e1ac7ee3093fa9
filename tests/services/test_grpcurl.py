"""grpcurl talks to the services with no .proto files, through server reflection."""

import base64
import json

from tests.support.data import image
from tests.support.grpcurl import grpcurl
from tests.support.services import RunningService


def test_list_shows_the_services(detector: RunningService) -> None:
    services = grpcurl(detector.address, "list").split()
    assert {"oricf.v1.Detector", "grpc.health.v1.Health"} <= set(services)


def test_describe_shows_the_contract(detector: RunningService) -> None:
    description = grpcurl(detector.address, "describe", "oricf.v1.DetectRequest")
    assert ".oricf.v1.Image image = 1;" in description
    assert "repeated string labels = 2;" in description


def test_detect_with_a_json_body(detector: RunningService) -> None:
    body = json.dumps({
        "image": {"data": base64.b64encode(image("person.jpg").read_bytes()).decode(),
                  "encoding": "jpeg"},
        "labels": ["person"],
    })
    answer = json.loads(grpcurl(detector.address, "oricf.v1.Detector/Detect", data=body))
    assert [d["label"] for d in answer["detections"]] == ["person"]
    assert "counts" not in answer and "annotated" not in answer


def test_health_check(detector: RunningService) -> None:
    answer = json.loads(grpcurl(detector.address, "grpc.health.v1.Health/Check"))
    assert answer["status"] == "SERVING"


def test_declared_models_answer_grpcurl_over_the_open_inference_protocol(
        models: RunningService) -> None:
    assert "inference.GRPCInferenceService" in grpcurl(models.address, "list").split()
    meta = json.loads(grpcurl(models.address, "inference.GRPCInferenceService/ModelMetadata",
                              data='{"name": "yolox-nano"}'))
    # The declaration frees the batch dimension (so the service can batch): -1.
    assert meta["inputs"] == [{"name": "images", "datatype": "FP32",
                               "shape": ["-1", "3", "416", "416"]}]
    # An encoded photo as one BYTES element: the server pre-processes it.
    body = json.dumps({"model_name": "yolox-nano", "inputs": [{
        "name": "images", "datatype": "BYTES", "shape": [1],
        "contents": {"bytes_contents": [
            base64.b64encode(image("person.jpg").read_bytes()).decode()]}}]})
    answer = json.loads(grpcurl(models.address, "inference.GRPCInferenceService/ModelInfer",
                                data=body))
    assert answer["outputs"][0]["shape"] == ["1", "3549", "85"]
    assert len(base64.b64decode(answer["raw_output_contents"][0])) == 3549 * 85 * 4
