"""Tensor data types and shapes as the Open Inference Protocol names them.

One table maps each protocol datatype to its numpy type, the typed-contents field that may
carry it, and the names the back ends use for it. Everything else (checks, conversions)
reads the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oricf.errors import InvalidInput


@dataclass(frozen=True)
class Datatype:
    name: str              # the protocol's name: "FP32"
    numpy: str             # numpy dtype, little-endian: "<f4"
    contents: str          # InferTensorContents field for typed contents ("" : raw only)
    onnx: str              # onnxruntime's type string: "tensor(float)"
    openvino: str          # openvino's element type name: "f32"


DATATYPES: dict[str, Datatype] = {d.name: d for d in (
    Datatype("BOOL", "?", "bool_contents", "tensor(bool)", "boolean"),
    Datatype("UINT8", "u1", "uint_contents", "tensor(uint8)", "u8"),
    Datatype("UINT16", "<u2", "uint_contents", "tensor(uint16)", "u16"),
    Datatype("UINT32", "<u4", "uint_contents", "tensor(uint32)", "u32"),
    Datatype("UINT64", "<u8", "uint64_contents", "tensor(uint64)", "u64"),
    Datatype("INT8", "i1", "int_contents", "tensor(int8)", "i8"),
    Datatype("INT16", "<i2", "int_contents", "tensor(int16)", "i16"),
    Datatype("INT32", "<i4", "int_contents", "tensor(int32)", "i32"),
    Datatype("INT64", "<i8", "int64_contents", "tensor(int64)", "i64"),
    Datatype("FP16", "<f2", "", "tensor(float16)", "f16"),
    Datatype("FP32", "<f4", "fp32_contents", "tensor(float)", "f32"),
    Datatype("FP64", "<f8", "fp64_contents", "tensor(double)", "f64"),
    Datatype("BYTES", "O", "bytes_contents", "tensor(string)", "string"),
)}
DATATYPE_NAMES = tuple(DATATYPES)
# numpy's limit: an array cannot have more dimensions.
MAX_DIMS = 64


def datatype(name: str) -> Datatype:
    try:
        return DATATYPES[name]
    except KeyError:
        raise InvalidInput(f"unknown datatype '{clip(name)}' "
                           f"(known: {', '.join(DATATYPE_NAMES)})") from None


def datatype_of(array: np.ndarray) -> Datatype:
    """The protocol datatype of a numpy array."""
    if array.dtype.kind in "OSU":
        return DATATYPES["BYTES"]
    for entry in DATATYPES.values():
        if entry.name != "BYTES" and np.dtype(entry.numpy) == array.dtype.newbyteorder("<"):
            return entry
    raise InvalidInput(f"no protocol datatype for numpy {array.dtype}")


def by_backend_name(field: str, value: str) -> Datatype:
    """The datatype a back end calls `value` (field: "onnx" or "openvino")."""
    for entry in DATATYPES.values():
        if getattr(entry, field) == value:
            return entry
    raise InvalidInput(f"the model uses a tensor type ORICF cannot carry: {value}")


@dataclass(frozen=True)
class TensorSpec:
    """A model input or output: name, datatype, shape (-1 for a free dimension)."""

    name: str
    datatype: str
    shape: tuple[int, ...]

    def accepts_shape(self, shape: Sequence[int]) -> bool:
        return len(shape) == len(self.shape) and all(
            want < 0 or want == got for want, got in zip(self.shape, shape, strict=True))

    def check(self, array: np.ndarray) -> None:
        """Refuses an array of the wrong datatype or shape, naming this tensor."""
        got = datatype_of(array).name
        if got != self.datatype:
            raise InvalidInput(f"input '{clip(self.name)}': datatype {got}, the model "
                               f"expects {self.datatype}")
        if not self.accepts_shape(array.shape):
            raise InvalidInput(f"input '{clip(self.name)}': shape {list(array.shape)}, the "
                               f"model expects {list(self.shape)} (-1: any size)")


def element_count(shape: Sequence[int]) -> int:
    if len(shape) > MAX_DIMS:
        raise InvalidInput(f"shape has {len(shape)} dimensions; at most {MAX_DIMS}")
    count = 1
    for dim in shape:
        if dim < 0:
            raise InvalidInput(f"shape {list(shape)}: dimensions must be >= 0")
        count *= dim
    return count


def check_input_shape(name: str, shape: Sequence[int]) -> None:
    """Refuses what no model can run on: too many dimensions, negative ones, and empty
    tensors (a zero dimension, which a network's reshapes fail on)."""
    if len(shape) > MAX_DIMS:
        raise InvalidInput(f"input '{clip(name)}': {len(shape)} dimensions; at most "
                           f"{MAX_DIMS}")
    if element_count(shape) == 0:
        raise InvalidInput(f"input '{clip(name)}': shape {list(shape)}: dimensions must be "
                           f"> 0 (an empty tensor)")


def input_bytes(type_name: str, shape: Sequence[int], raw: bytes | None = None) -> int:
    """The bytes an input tensor takes as an array, from its datatype and shape (BYTES: its
    raw contents' length), known before it is converted."""
    kind = datatype(type_name)
    if kind.name == "BYTES":
        return len(raw) if raw is not None else element_count(shape) * 8
    return element_count(shape) * np.dtype(kind.numpy).itemsize


def clip(text: str, limit: int = 64) -> str:
    """Caller-supplied text as it may appear in an error message: never unbounded."""
    return text if len(text) <= limit else text[:limit] + "..."
