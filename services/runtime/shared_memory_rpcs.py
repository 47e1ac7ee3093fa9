"""The system shared-memory RPCs of inference.GRPCInferenceService over one registry.

`oricf serve models` serves them beside ModelInfer; the detector serves them alone (its
other Open Inference RPCs answer UNIMPLEMENTED), so that a client registers regions the same
way with either and then names them in ModelInfer or in Detect.
"""

from __future__ import annotations

import grpc

from oricf.errors import InvalidInput
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.services.runtime.shared_memory import SharedMemoryRegistry


class SharedMemoryServicer(oip_grpc.GRPCInferenceServiceServicer):
    def __init__(self, registry: SharedMemoryRegistry | None) -> None:
        """registry None: the extension is switched off (every call INVALID_ARGUMENT)."""
        self.shared_memory = registry

    def _registry(self) -> SharedMemoryRegistry:
        if self.shared_memory is None:
            raise InvalidInput("system shared memory is off on this server "
                               "(shared_memory.enabled)")
        return self.shared_memory

    def SystemSharedMemoryStatus(self, request: oip.SystemSharedMemoryStatusRequest,
                                 context: grpc.ServicerContext
                                 ) -> oip.SystemSharedMemoryStatusResponse:
        response = oip.SystemSharedMemoryStatusResponse()
        for region in self._registry().status(request.name):
            response.regions[region.name].CopyFrom(
                oip.SystemSharedMemoryStatusResponse.RegionStatus(
                    name=region.name, key=region.key, offset=region.offset,
                    byte_size=region.byte_size))
        return response

    def SystemSharedMemoryRegister(self, request: oip.SystemSharedMemoryRegisterRequest,
                                   context: grpc.ServicerContext
                                   ) -> oip.SystemSharedMemoryRegisterResponse:
        self._registry().register(request.name, request.key, request.offset,
                                  request.byte_size)
        return oip.SystemSharedMemoryRegisterResponse()

    def SystemSharedMemoryUnregister(self, request: oip.SystemSharedMemoryUnregisterRequest,
                                     context: grpc.ServicerContext
                                     ) -> oip.SystemSharedMemoryUnregisterResponse:
        self._registry().unregister(request.name)
        return oip.SystemSharedMemoryUnregisterResponse()
