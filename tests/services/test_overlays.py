"""The shipped service overlays (configs/services/overlays/) fit the services they are for."""

from __future__ import annotations

from typing import Any

import pytest

from oricf.config import config_dir
from oricf.imaging import encode_image
from oricf.services.local import local_service, service_config
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.services import CHANNEL_OPTIONS

OVERLAYS = config_dir() / "services" / "overlays"


def overlaid(service: str, overlay: str) -> Any:
    return service_config(service, overlays=[OVERLAYS / overlay])


@pytest.mark.parametrize("service", ["detector", "asr", "llm", "models"])
@pytest.mark.parametrize("overlay", ["tls.yaml", "kubernetes.yaml"])
def test_the_server_overlays_fit_every_service(service: str, overlay: str) -> None:
    server = overlaid(service, overlay).server
    if overlay == "tls.yaml":
        assert server.tls.client_ca is not None and server.auth.file is not None
        assert not server.reflection
    else:
        assert server.health_listen is not None


def test_the_fleet_overlay_serves_the_320_model_to_many_robots() -> None:
    import grpc

    config = overlaid("detector", "fleet.yaml")
    assert config.model.resolve() == (config_dir() / "models" / "yolox-nano-320.yaml").resolve()
    assert config.server.max_concurrent_rpcs >= 12
    (frame,) = video_frames([0], (640, 480))
    request = detector_pb2.DetectRequest(
        image=common_pb2.Image(data=encode_image(frame, "jpeg"), encoding="jpeg"),
        labels=["person"])
    with local_service("detector", config) as host, grpc.insecure_channel(
            f"127.0.0.1:{host.port}", options=CHANNEL_OPTIONS) as channel:
        stub = detector_pb2_grpc.DetectorStub(channel)
        info = stub.GetModelInfo(common_pb2.GetModelInfoRequest())
        response = stub.Detect(request)
    assert info.model == "yolox-nano-320"
    # The first frame of the pedestrian video: three people walk in it.
    assert count(response, "person") >= 3
    assert (response.image_width, response.image_height) == (640, 480)
