"""The gRPC side of a `Service` class, derived from its proto: the one servicer every service
shares.

Each RPC of the proto is served by the class's method of the same name in snake_case, with
the proto's own message classes parsing and serializing; RPCs the class lacks answer
UNIMPLEMENTED (grpc's own answer for an unknown method). Every handler first asks the model
slot for the model, so a call (or a message of a client stream) that arrives before
`load()` has returned, or once the service is closing, is UNAVAILABLE. GetModelInfo, when
the proto has it, is answered from `info()` whether the model has loaded or not. Errors
become status codes in the interceptor every handler runs in (errors.py).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from typing import Any

import grpc
from google.protobuf import message_factory
from google.protobuf.descriptor import MethodDescriptor

from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.services.runtime.info import model_info_response
from oricf.services.runtime.model import ModelSlot
from oricf.services.runtime.parts import ServiceParts
from oricf.services.runtime.service import Service
from oricf.services.runtime.shared_memory_rpcs import SharedMemoryServicer
from oricf.services.spec import ServiceSpec

MODEL_INFO = "GetModelInfo"
Behavior = Callable[[Any, Any], Any]


def service_parts(cls: type[Service[Any]], spec: ServiceSpec | None = None) -> ServiceParts:
    """What the runtime serves of the class: under spec (its entry in SERVICES), or under
    its own name and proto for a service that is in no list (port 0)."""
    spec = spec or ServiceSpec(cls.name, cls.proto.full_name, 0)
    if (spec.name, spec.grpc_service) != (cls.name, cls.proto.full_name):
        raise TypeError(f"{cls.__qualname__} serves {cls.proto.full_name} as '{cls.name}', "
                        f"not {spec.grpc_service} as '{spec.name}'")
    return ServiceParts(spec, config_schema=cls.config_schema, create_model=cls,
                        add_servicer=add_service, message_streams=cls.message_streams)


def add_service(server: grpc.Server, slot: ModelSlot[Service[Any]], config: Any) -> None:
    """The service's RPCs on server, its batchers attached to the slot (drained before the
    model closes) and, when it has a registry, the shared-memory RPCs."""
    service = slot.peek()
    name = service.proto.full_name
    handlers = {method.name: _handler(method, behavior)
                for method in service.proto.methods
                if (behavior := _behavior(service, slot, method)) is not None}
    server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(name, handlers),))
    server.add_registered_method_handlers(name, handlers)
    for batcher in service.batchers:
        slot.attach(batcher)
    if service.shared_memory is not None:  # clients register the regions requests name
        oip_grpc.add_GRPCInferenceServiceServicer_to_server(
            SharedMemoryServicer(service.shared_memory), server)


def handler_name(rpc: str) -> str:
    """The method that serves an RPC: "DetectStream" -> "detect_stream"."""
    return re.sub(r"(?<!^)(?=[A-Z])", "_", rpc).lower()


def _behavior(service: Service[Any], slot: ModelSlot[Service[Any]],
              method: MethodDescriptor) -> Behavior | None:
    serve: Behavior | None = getattr(service, handler_name(method.name), None)
    if serve is None:
        if method.name != MODEL_INFO:
            return None
        return lambda request, context: model_info_response(service.name, slot)
    if method.client_streaming:
        return lambda requests, context: serve(_each_ready(requests, slot), context)

    def once_ready(request: Any, context: Any) -> Any:
        slot.get()  # NotReady (UNAVAILABLE) until loaded
        return serve(request, context)

    return once_ready


def _each_ready(requests: Iterator[Any], slot: ModelSlot[Any]) -> Iterator[Any]:
    """The requests of a client stream, each refused while the model is not ready."""
    for request in requests:
        slot.get()
        yield request


def _handler(method: MethodDescriptor, behavior: Behavior) -> grpc.RpcMethodHandler:
    kind = {(False, False): grpc.unary_unary_rpc_method_handler,
            (False, True): grpc.unary_stream_rpc_method_handler,
            (True, False): grpc.stream_unary_rpc_method_handler,
            (True, True): grpc.stream_stream_rpc_method_handler}
    make = kind[method.client_streaming, method.server_streaming]
    return make(behavior,
                request_deserializer=message_factory.GetMessageClass(
                    method.input_type).FromString,
                response_serializer=message_factory.GetMessageClass(
                    method.output_type).SerializeToString)
