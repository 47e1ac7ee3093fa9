"""Tensors on the Open Inference Protocol wire <-> numpy arrays, for servers and clients.

A tensor travels as name, datatype and shape plus either raw bytes (flattened, row-major,
little-endian; BYTES elements each prefixed by a 4-byte little-endian length) or typed
contents (the repeated field of its datatype). Every count is checked against the shape
before anything is allocated, and errors name the tensor.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.models.shared_memory import (
    BYTE_SIZE,
    OFFSET,
    REGION,
    SharedMemoryRef,
    tensor_ref,
)
from oricf.models.tensors import (
    Datatype,
    check_input_shape,
    clip,
    datatype,
    datatype_of,
    element_count,
    input_bytes,
)
from oricf.oip import open_inference_grpc_pb2 as oip


def _bytes_elements(raw: bytes, count: int, name: str) -> np.ndarray:
    items: list[bytes] = []
    view, offset = memoryview(raw), 0
    while offset < len(raw):
        if offset + 4 > len(raw):
            raise InvalidInput(f"tensor '{name}': BYTES element {len(items)} has a cut "
                               f"length prefix")
        size = int.from_bytes(view[offset:offset + 4], "little")
        offset += 4
        if offset + size > len(raw):
            raise InvalidInput(f"tensor '{name}': BYTES element {len(items)} claims {size:,} "
                               f"bytes, {len(raw) - offset:,} remain")
        items.append(bytes(view[offset:offset + size]))
        offset += size
    if len(items) != count:
        raise InvalidInput(f"tensor '{name}': {len(items)} BYTES elements, its shape needs "
                           f"{count}")
    array = np.empty(count, dtype=object)
    array[:] = items
    return array


def from_raw(name: str, type_name: str, shape: Sequence[int], raw: bytes) -> np.ndarray:
    name = clip(name)
    kind = datatype(type_name)
    count = element_count(shape)
    if kind.name == "BYTES":
        return _bytes_elements(raw, count, name).reshape(shape)
    expected = count * np.dtype(kind.numpy).itemsize
    if len(raw) != expected:
        raise InvalidInput(f"tensor '{name}': {len(raw):,} bytes, but {kind.name} "
                           f"{list(shape)} needs {expected:,}")
    return np.frombuffer(raw, dtype=kind.numpy).reshape(shape)


def from_contents(name: str, type_name: str, shape: Sequence[int],
                  contents: oip.InferTensorContents) -> np.ndarray:
    name = clip(name)
    kind = datatype(type_name)
    count = element_count(shape)
    if not kind.contents:
        raise InvalidInput(f"tensor '{name}': {kind.name} travels only as raw contents")
    values = getattr(contents, kind.contents)
    if len(values) != count:
        raise InvalidInput(f"tensor '{name}': {len(values)} values in {kind.contents}, but "
                           f"{list(shape)} needs {count}")
    if kind.name == "BYTES":
        array = np.empty(count, dtype=object)
        array[:] = list(values)
        return array.reshape(shape)
    try:
        return np.asarray(values, dtype=np.dtype(kind.numpy)).reshape(shape)
    except OverflowError:
        raise InvalidInput(f"tensor '{name}': a value is out of range for {kind.name}") from None


def to_raw(array: np.ndarray) -> tuple[Datatype, bytes]:
    kind = datatype_of(array)
    if kind.name == "BYTES":
        parts = []
        for item in array.reshape(-1):
            data = item.encode() if isinstance(item, str) else bytes(item)
            parts += [len(data).to_bytes(4, "little"), data]
        return kind, b"".join(parts)
    return kind, np.ascontiguousarray(array, dtype=np.dtype(kind.numpy)).tobytes()


# Reads the bytes a shared-memory reference names (the server's registry).
ReadShared = Callable[[SharedMemoryRef], bytes]


def _sources(request: oip.ModelInferRequest) -> list[int | SharedMemoryRef]:
    """Where each input's bytes are: an index into raw_input_contents, or a shared-memory
    region. Raw contents are the inputs' that are not in shared memory, in order (what
    tritonclient sends); -1: the input has typed contents."""
    raw = request.raw_input_contents
    sources: list[int | SharedMemoryRef] = []
    for tensor in request.inputs:
        ref = tensor_ref(tensor.parameters, f"input '{clip(tensor.name)}'")
        sources.append(ref if ref is not None else
                       sum(isinstance(s, int) for s in sources) if raw else -1)
    in_wire = sum(isinstance(s, int) for s in sources)
    if raw and len(raw) != in_wire:
        raise InvalidInput(f"raw_input_contents has {len(raw)} entries for {in_wire} inputs "
                           f"not in shared memory")
    return sources


def request_inputs(request: oip.ModelInferRequest, read: ReadShared | None = None
                   ) -> dict[str, np.ndarray]:
    """A request's input tensors, raw, typed or in shared memory (read by `read`);
    duplicates and miscounts refused."""
    raw = request.raw_input_contents
    tensors: dict[str, np.ndarray] = {}
    for tensor, source in zip(request.inputs, _sources(request), strict=True):
        name = tensor.name
        if name in tensors:
            raise InvalidInput(f"input '{clip(name)}' is given twice")
        check_input_shape(name, tensor.shape)
        if isinstance(source, SharedMemoryRef):
            if read is None:
                raise InvalidInput(f"input '{clip(name)}': shared memory is not served here")
            if tensor.HasField("contents"):
                raise InvalidInput(f"input '{clip(name)}': contents and shared memory are "
                                   f"both set")
            # Checked before reading: the copy is never larger than the tensor it makes.
            needed = input_bytes(tensor.datatype, tensor.shape, b"")
            if tensor.datatype != "BYTES" and source.byte_size != needed:
                raise InvalidInput(f"input '{clip(name)}': shared_memory_byte_size "
                                   f"{source.byte_size:,}, but {tensor.datatype} "
                                   f"{list(tensor.shape)} takes {needed:,} bytes")
            tensors[name] = from_raw(name, tensor.datatype, tensor.shape, read(source))
        elif source >= 0:
            if tensor.HasField("contents"):
                raise InvalidInput(f"input '{clip(name)}': contents and raw_input_contents "
                                   f"are both set")
            tensors[name] = from_raw(name, tensor.datatype, tensor.shape, raw[source])
        else:
            tensors[name] = from_contents(name, tensor.datatype, tensor.shape,
                                          tensor.contents)
    return tensors


def request_bytes(request: oip.ModelInferRequest) -> int:
    """The bytes a request's input tensors take as arrays, known before any is converted
    (for a memory budget); shapes no model can run on are refused first."""
    raw = request.raw_input_contents
    total = 0
    for tensor, source in zip(request.inputs, _sources(request), strict=True):
        check_input_shape(tensor.name, tensor.shape)
        if tensor.datatype == "BYTES" and isinstance(source, SharedMemoryRef):
            total += source.byte_size
            continue
        # Only a BYTES tensor's size needs its contents: reading an entry copies it.
        contents = raw[source] if tensor.datatype == "BYTES" and isinstance(source, int) \
            and source >= 0 else None
        total += input_bytes(tensor.datatype, tensor.shape, contents)
    return total


Parameters = dict[str, Any]


def infer_request(model: str, inputs: dict[str, np.ndarray],
                  outputs: Sequence[str] | Mapping[str, Parameters] = (),
                  request_id: str = "", parameters: Parameters | None = None, *,
                  placed: Mapping[str, SharedMemoryRef] | None = None,
                  input_parameters: Mapping[str, Parameters] | None = None
                  ) -> oip.ModelInferRequest:
    """A ModelInferRequest with raw contents (the compact form every server accepts).
    outputs: names, or names -> their parameters; placed: the inputs (by name) whose bytes
    are in shared memory (and, for outputs, where each goes); input_parameters: by name."""
    request = oip.ModelInferRequest(model_name=model, id=request_id)
    _add_tensors(request.inputs, request.raw_input_contents, inputs, placed)
    for tensor in request.inputs:
        for key, value in (input_parameters or {}).get(tensor.name, {}).items():
            set_parameter(tensor.parameters[key], value)
    wanted = outputs if isinstance(outputs, Mapping) else {name: {} for name in outputs}
    for name, settings in wanted.items():
        output = request.outputs.add(name=name)
        for key, value in settings.items():
            set_parameter(output.parameters[key], value)
    for key, value in (parameters or {}).items():
        set_parameter(request.parameters[key], value)
    return request


def _set_ref(parameters: Any, ref: SharedMemoryRef) -> None:
    set_parameter(parameters[REGION], ref.region)
    set_parameter(parameters[OFFSET], ref.offset)
    set_parameter(parameters[BYTE_SIZE], ref.byte_size)


def infer_response(model: str, outputs: dict[str, np.ndarray], request_id: str = "",
                   placed: Mapping[str, SharedMemoryRef] | None = None
                   ) -> oip.ModelInferResponse:
    """The response: raw contents for every output but those placed in shared memory, which
    carry its parameters instead (as Triton answers)."""
    response = oip.ModelInferResponse(model_name=model, id=request_id)
    _add_tensors(response.outputs, response.raw_output_contents, outputs, placed)
    return response


def _add_tensors(tensors: Any, contents: Any, arrays: dict[str, np.ndarray],
                 placed: Mapping[str, SharedMemoryRef] | None) -> None:
    """Each array as a tensor entry (name, datatype, shape) plus its raw contents, or, if
    placed in shared memory, with the region's parameters instead."""
    for name, array in arrays.items():
        ref = (placed or {}).get(name)
        if ref is None:
            kind, raw = to_raw(array)
            tensors.add(name=name, datatype=kind.name, shape=array.shape)
            contents.append(raw)
        else:
            tensor = tensors.add(name=name, datatype=datatype_of(array).name,
                                 shape=array.shape)
            _set_ref(tensor.parameters, ref)


def response_outputs(response: oip.ModelInferResponse,
                     asked: Mapping[str, SharedMemoryRef] | None = None
                     ) -> dict[str, np.ndarray]:
    """A response's output tensors, raw or typed, in order; those in shared memory are left
    out (shared_outputs says where they are). asked: the outputs the request placed in
    shared memory, which Triton answers without their parameters and with an empty raw
    entry each (ORICF's server names the region and leaves the entry out)."""
    raw = list(response.raw_output_contents)
    placed = [_placed(t, asked) for t in response.outputs]
    wire = [t for t, p in zip(response.outputs, placed, strict=True) if not p]
    if raw and len(raw) == len(placed) != len(wire):  # Triton's layout: an entry per output
        raw = [r for r, p in zip(raw, placed, strict=True) if not p]
    if raw and len(raw) != len(wire):
        raise InvalidInput(f"raw_output_contents has {len(raw)} entries for "
                           f"{len(wire)} outputs not in shared memory")
    return {t.name: (from_raw(t.name, t.datatype, t.shape, raw[i]) if raw else
                     from_contents(t.name, t.datatype, t.shape, t.contents))
            for i, t in enumerate(wire)}


def _placed(tensor: oip.ModelInferResponse.InferOutputTensor,
            asked: Mapping[str, SharedMemoryRef] | None) -> SharedMemoryRef | None:
    ref = tensor_ref(tensor.parameters, f"output '{clip(tensor.name)}'")
    return ref if ref is not None else (asked or {}).get(tensor.name)


def shared_outputs(response: oip.ModelInferResponse,
                   asked: Mapping[str, SharedMemoryRef] | None = None
                   ) -> dict[str, tuple[str, list[int], SharedMemoryRef]]:
    """The outputs placed in shared memory: name -> (datatype, shape, where); where the
    response does not say (Triton), where the request asked (asked)."""
    found = {}
    for tensor in response.outputs:
        ref = _placed(tensor, asked)
        if ref is not None:
            found[tensor.name] = (tensor.datatype, list(tensor.shape), ref)
    return found


def set_parameter(parameter: oip.InferParameter, value: Any) -> None:
    if isinstance(value, bool):
        parameter.bool_param = value
    elif isinstance(value, int):
        parameter.int64_param = value
    elif isinstance(value, float):
        parameter.double_param = value
    else:
        parameter.string_param = str(value)


def parameter_value(parameter: oip.InferParameter) -> Any:
    choice = parameter.WhichOneof("parameter_choice")
    return getattr(parameter, choice) if choice else None
