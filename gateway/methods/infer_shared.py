"""Infer through system shared memory: how large the model's output is (ModelMetadata, so
that a slot of the ring can hold it as well as the input), and the outputs the server wrote
into the slot."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import grpc
import numpy as np

from oricf.gateway.endpoints.shared_memory import PASSING
from oricf.models.shared_memory import OwnedRegion, SharedMemoryRef
from oricf.models.tensors import DATATYPES
from oricf.models.wire import shared_outputs
from oricf.oip import open_inference_grpc_pb2 as oip

METADATA_TIMEOUT_S = 2.0


class NotNow(Exception):
    """The server could not answer ModelMetadata this time (starting, busy, gone): ask again
    on a later call rather than take the output off shared memory for good."""


def output_bytes(target: Any, model: str, output: str) -> int | None:
    """The bytes of one batch of the named output, None if the server cannot say (no
    metadata, a free dimension other than the batch, a BYTES output)."""
    try:
        meta = target.stub.ModelMetadata(oip.ModelMetadataRequest(name=model),
                                         timeout=METADATA_TIMEOUT_S, metadata=target.metadata)
    except grpc.RpcError as error:
        if error.code() in PASSING:
            raise NotNow from error
        return None
    for tensor in meta.outputs:
        if tensor.name != output or tensor.datatype not in DATATYPES \
                or tensor.datatype == "BYTES":
            continue
        shape = [1 if i == 0 and d == -1 else d for i, d in enumerate(tensor.shape)]
        if any(d < 0 for d in shape):
            return None
        return int(np.prod(shape)) * np.dtype(DATATYPES[tensor.datatype].numpy).itemsize
    return None


def placed_outputs(response: oip.ModelInferResponse, region: OwnedRegion,
                   asked: Mapping[str, SharedMemoryRef] | None = None
                   ) -> dict[str, np.ndarray]:
    """The outputs the server wrote into the region, copied out of it (the slot is reused
    by the next call); asked: where the request placed them (Triton's answer does not say)."""
    found = {}
    for name, (datatype, shape, ref) in shared_outputs(response, asked).items():
        kind = np.dtype(DATATYPES[datatype].numpy) if datatype in DATATYPES else None
        count = int(np.prod(shape))
        if kind is None or kind == np.dtype(object) or count * kind.itemsize > ref.byte_size \
                or ref.offset + ref.byte_size > region.byte_size:
            raise ValueError(f"output '{name[:64]}' in shared memory: {datatype} {shape} "
                             f"does not fit where the server says it is")
        view = region.view(ref.offset, count * kind.itemsize)
        found[name] = np.frombuffer(view, kind).reshape(shape).copy()
    return found
