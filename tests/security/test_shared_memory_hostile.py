"""Hostile shared memory against the real `oricf serve models` and detector: keys that try
to leave /dev/shm, links, other users' objects, regions past their object, unregistered
regions, lying sizes, objects shrunk after registering, full registries; and fuzzing of the
three registry RPCs and of the tensors' shared-memory parameters. Every one is refused with
a client's status, never INTERNAL, never a read outside the region; the service stays up."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import grpc
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.models.shared_memory import OwnedRegion
from oricf.models.wire import infer_request, set_parameter
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.security.test_fuzz import ACCEPTABLE, serialized
from tests.support.services import RunningService, running_service

IMAGE_BYTES = 3 * 416 * 416 * 4
INVALID = grpc.StatusCode.INVALID_ARGUMENT
LIMITS = {"shared_memory": {"max_regions": 4, "max_total_mb": 16}}


@pytest.fixture(scope="module")
def models_few_regions() -> Iterator[RunningService]:
    with running_service("models", LIMITS) as service:
        yield service


@pytest.fixture(scope="module")
def detector_few_regions() -> Iterator[RunningService]:
    with running_service("detector", LIMITS) as service:
        yield service


@pytest.fixture
def stub(models_few_regions: RunningService) -> Iterator[oip_grpc.GRPCInferenceServiceStub]:
    stub = oip_grpc.GRPCInferenceServiceStub(models_few_regions.channel)
    yield stub
    stub.SystemSharedMemoryUnregister(oip.SystemSharedMemoryUnregisterRequest())


@pytest.fixture
def region() -> Iterator[OwnedRegion]:
    owned = OwnedRegion(IMAGE_BYTES)
    yield owned
    owned.close()


def refused(call: object, code: grpc.StatusCode = INVALID) -> str:
    with pytest.raises(grpc.RpcError) as caught:
        call()  # type: ignore[operator]
    assert caught.value.code() == code, caught.value.details()
    return str(caught.value.details())


def register(stub: oip_grpc.GRPCInferenceServiceStub, name: str, key: str,
             byte_size: int, offset: int = 0) -> None:
    stub.SystemSharedMemoryRegister(oip.SystemSharedMemoryRegisterRequest(
        name=name, key=key, offset=offset, byte_size=byte_size), timeout=10)


def image_request(ref_region: str, byte_size: int, offset: int = 0,
                  shape: tuple[int, ...] = (1, 3, 416, 416)) -> oip.ModelInferRequest:
    request = infer_request("yolox-nano", {"images": np.zeros(shape, np.float32)})
    del request.raw_input_contents[:]
    parameters = request.inputs[0].parameters
    set_parameter(parameters["shared_memory_region"], ref_region)
    set_parameter(parameters["shared_memory_byte_size"], byte_size)
    set_parameter(parameters["shared_memory_offset"], offset)
    return request


@pytest.mark.parametrize("key", ["../../etc/passwd", "/../etc/passwd", "a/b", "/", "",
                                 ".hidden", "x" * 300, "/dev/shm/x", "naïve"])
def test_keys_that_are_not_plain_names_are_refused(
        stub: oip_grpc.GRPCInferenceServiceStub, key: str) -> None:
    assert "shared-memory key" in refused(lambda: register(stub, "r", key, 16))


def test_links_missing_objects_and_other_users_objects_are_refused(
        stub: oip_grpc.GRPCInferenceServiceStub, tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_bytes(b"s" * 64)
    link = Path("/dev/shm") / f"oricf_test_link_{os.getpid()}"
    link.symlink_to(secret)
    try:
        refused(lambda: register(stub, "link", link.name, 16))
    finally:
        link.unlink()
    refused(lambda: register(stub, "missing", f"oricf_test_missing_{os.getpid()}", 16))
    if os.getuid() == 0:  # an object of another user (only root can make one here)
        foreign = Path("/dev/shm") / f"oricf_test_foreign_{os.getpid()}"
        foreign.write_bytes(b"f" * 64)
        os.chown(foreign, 65534, 65534)
        try:
            assert "another user" in refused(lambda: register(stub, "f", foreign.name, 16))
        finally:
            foreign.unlink()


def test_regions_past_their_object_duplicates_and_full_registries_are_refused(
        stub: oip_grpc.GRPCInferenceServiceStub, region: OwnedRegion) -> None:
    key = region.key
    assert "runs past" in refused(lambda: register(stub, "big", key, IMAGE_BYTES + 1))
    refused(lambda: register(stub, "off", key, 16, offset=IMAGE_BYTES))
    refused(lambda: register(stub, "zero", key, 0))
    refused(lambda: register(stub, "huge", key, 2**64 - 1, offset=2**63))
    register(stub, "one", key, 16)
    assert "already registered" in refused(lambda: register(stub, "one", key, 16))
    for name in ("two", "three", "four"):
        register(stub, name, key, 16)
    refused(lambda: register(stub, "five", key, 16), grpc.StatusCode.RESOURCE_EXHAUSTED)
    stub.SystemSharedMemoryUnregister(oip.SystemSharedMemoryUnregisterRequest())
    large = OwnedRegion(10 * 2**20)  # two of them are more than max_total_mb (16)
    try:
        register(stub, "large", large.key, large.byte_size)
        assert "max_total_mb" in refused(
            lambda: register(stub, "larger", large.key, large.byte_size),
            grpc.StatusCode.RESOURCE_EXHAUSTED)
    finally:
        large.close()
    refused(lambda: stub.SystemSharedMemoryStatus(
        oip.SystemSharedMemoryStatusRequest(name="nobody")))


def test_tensors_naming_regions_badly_are_refused(
        stub: oip_grpc.GRPCInferenceServiceStub, region: OwnedRegion) -> None:
    register(stub, "image", region.key, IMAGE_BYTES)
    register(stub, "small", region.key, 100)
    assert "no shared-memory region" in refused(
        lambda: stub.ModelInfer(image_request("unknown", IMAGE_BYTES)))
    assert "runs past" in refused(lambda: stub.ModelInfer(image_request("image", IMAGE_BYTES,
                                                                        offset=16)))
    # a region smaller than the tensor it is said to hold
    assert "runs past" in refused(lambda: stub.ModelInfer(image_request("small", IMAGE_BYTES)))
    assert "takes" in refused(lambda: stub.ModelInfer(image_request("image", 100)))
    refused(lambda: stub.ModelInfer(image_request("image", -5)))
    # an output region too small for the output
    request = image_request("image", IMAGE_BYTES)
    output = request.outputs.add(name="output")
    set_parameter(output.parameters["shared_memory_region"], "small")
    set_parameter(output.parameters["shared_memory_byte_size"], 100)
    assert "output takes" in refused(lambda: stub.ModelInfer(request))
    # the right reference works
    assert stub.ModelInfer(image_request("image", IMAGE_BYTES), timeout=30).outputs


def test_an_object_shrunk_after_registering_is_a_short_read_not_a_crash(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    owned = OwnedRegion(IMAGE_BYTES)
    try:
        register(stub, "shrinking", owned.key, IMAGE_BYTES)
        os.truncate(Path("/dev/shm") / owned.key.lstrip("/"), 16)
        assert "shrank" in refused(lambda: stub.ModelInfer(image_request("shrinking",
                                                                         IMAGE_BYTES)))
    finally:
        owned.close()
    assert stub.ServerReady(oip.ServerReadyRequest()).ready


def test_detect_by_region_refuses_what_it_cannot_read(detector_few_regions: RunningService) -> None:
    stub = detector_pb2_grpc.DetectorStub(detector_few_regions.channel)
    shm = oip_grpc.GRPCInferenceServiceStub(detector_few_regions.channel)
    owned = OwnedRegion(640 * 480 * 3)
    try:
        register(shm, "frame", owned.key, 640 * 480 * 3)

        def detect(region: str, byte_size: int, data: bytes = b"", offset: int = 0) -> None:
            stub.Detect(detector_pb2.DetectRequest(
                image=common_pb2.Image(data=data, encoding="bgr8", width=640, height=480),
                image_region=detector_pb2.SharedMemoryRef(region=region, offset=offset,
                                                          byte_size=byte_size)), timeout=30)

        refused(lambda: detect("nobody", 640 * 480 * 3))
        refused(lambda: detect("frame", 640 * 480 * 3, offset=1))
        refused(lambda: detect("frame", 2**63))
        refused(lambda: detect("frame", 100))  # fewer bytes than 640x480 bgr8 takes
        refused(lambda: detect("frame", 640 * 480 * 3, data=b"x"))
        refused(lambda: detect("../x", 10))
        detect("frame", 640 * 480 * 3)  # a black frame: no detections, no error
    finally:
        shm.SystemSharedMemoryUnregister(oip.SystemSharedMemoryUnregisterRequest())
        owned.close()


PARAMETER_VALUES = st.one_of(st.text(max_size=20), st.integers(-(2**63), 2**63 - 1),
                             st.booleans(), st.floats(allow_nan=True),
                             st.sampled_from(["image", "small", "", "../x"]))


@settings(max_examples=120, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(st.dictionaries(st.sampled_from(["shared_memory_region", "shared_memory_offset",
                                        "shared_memory_byte_size"]), PARAMETER_VALUES),
       st.booleans())
def test_fuzzed_shared_memory_parameters_get_client_errors(
        models_few_regions: RunningService, values: dict[str, object], on_output: bool) -> None:
    stub = oip_grpc.GRPCInferenceServiceStub(models_few_regions.channel)
    request = infer_request("yolox-nano", {"images": np.zeros((1, 3, 416, 416), np.float32)})
    target = request.outputs.add(name="output") if on_output else request.inputs[0]
    if not on_output:
        del request.raw_input_contents[:]
    for key, value in values.items():
        set_parameter(target.parameters[key], value)
    try:
        stub.ModelInfer(request, timeout=30)
    except grpc.RpcError as error:
        assert error.code() in ACCEPTABLE, error.details()


@pytest.mark.parametrize("rpc", ["SystemSharedMemoryRegister", "SystemSharedMemoryStatus",
                                 "SystemSharedMemoryUnregister"])
def test_fuzzed_registry_calls_on_the_detector_get_client_errors(
        detector_few_regions: RunningService, rpc: str) -> None:
    method = oip.DESCRIPTOR.services_by_name["GRPCInferenceService"].methods_by_name[rpc]
    call = detector_few_regions.channel.unary_unary(f"/inference.GRPCInferenceService/{rpc}")

    @settings(max_examples=60, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.one_of(st.binary(max_size=128), serialized(method.input_type)))
    def fuzz(payload: bytes) -> None:
        try:
            call(payload, timeout=30)
        except grpc.RpcError as error:
            assert error.code() in ACCEPTABLE, error.details()

    fuzz()
    assert detector_pb2_grpc.DetectorStub(detector_few_regions.channel).GetModelInfo(
        common_pb2.GetModelInfoRequest(), timeout=10).model
