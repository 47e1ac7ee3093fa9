"""How much room a shared-memory slot keeps for the model's output, asked of the real
`oricf serve models`: known when the server says, never asked again when it cannot say,
and asked again later when the server could not answer this time."""

from __future__ import annotations

from types import SimpleNamespace

import grpc
import pytest

from oricf.gateway.methods.infer_shared import NotNow, output_bytes
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.support.processes import free_port
from tests.support.services import RunningService


def target(channel: grpc.Channel) -> SimpleNamespace:
    return SimpleNamespace(stub=oip_grpc.GRPCInferenceServiceStub(channel), metadata=())


def test_the_output_room_is_the_declared_tensor(models: RunningService) -> None:
    # YOLOX-Nano's `output`: [1, 3549, 85] float32
    assert output_bytes(target(models.channel), "yolox-nano", "output") == 3549 * 85 * 4


def test_what_the_server_cannot_say_is_none(models: RunningService) -> None:
    assert output_bytes(target(models.channel), "yolox-nano", "no-such-output") is None
    assert output_bytes(target(models.channel), "no-such-model", "output") is None


def test_a_server_that_cannot_answer_now_is_asked_again_later() -> None:
    with grpc.insecure_channel(f"127.0.0.1:{free_port()}") as nobody, pytest.raises(NotNow):
        output_bytes(target(nobody), "yolox-nano", "output")
