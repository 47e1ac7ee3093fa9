"""The messages an agent may send, as flat fields (`linear.x` of a Twist): the types of the
table of types (oricf.gateway.topics.types) that an agent's target may name (`command`),
their fields read from their definitions, each of a kind: float, int, bool or text.

An agent gives a message as JSON (`{"linear": {"x": 0.2}}`); it is flattened, every field
checked against the type's table (unknown fields refused, numbers finite, text bounded), and
only then made into a ROS message or a text line. Nothing in a message is ever evaluated.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from typing import Any

from oricf.errors import InvalidInput
from oricf.gateway.topics import definitions
from oricf.gateway.topics.convert import nested

# a primitive ROS type -> the kind of value an agent gives for it
KINDS = {"float32": "float", "float64": "float", "bool": "bool", "string": "text",
         **{f"{sign}int{bits}": "int" for sign in ("", "u") for bits in (8, 16, 32, 64)}}
MAX_TEXT = 2000
FLOAT_MAX = sys.float_info.max
MAX_DEPTH = 4


def flatten(message: Any, prefix: str = "", depth: int = 0) -> dict[str, Any]:
    """{"linear": {"x": 0.2}} -> {"linear.x": 0.2}; anything but an object is refused."""
    if not isinstance(message, Mapping):
        raise InvalidInput(f"message{' field ' + prefix if prefix else ''} must be a JSON "
                           f"object, got {type(message).__name__}")
    if depth >= MAX_DEPTH:
        raise InvalidInput("message nests too deep")
    flat: dict[str, Any] = {}
    for key, value in message.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, f"{name}.", depth + 1))
        else:
            flat[name] = value
    return flat


def fields_of(type_: str) -> dict[str, str]:
    """A type's fields by dotted name and their kind ({"linear.x": "float", ...})."""
    return {name: KINDS[primitive]
            for name, primitive in definitions.primitive_fields(type_).items()}


def check_fields(type_: str, flat: dict[str, Any]) -> dict[str, Any]:
    """The message's fields, each of the kind its type says; every field of the type
    present (missing ones zero, false or empty)."""
    fields = fields_of(type_)
    unknown = sorted(set(flat) - set(fields))
    if unknown:
        raise InvalidInput(f"{type_} has no field {', '.join(map(repr, unknown))[:200]} "
                           f"(fields: {', '.join(fields)})")
    return {name: _value(name, kind, flat[name]) if name in flat else DEFAULTS[kind]
            for name, kind in fields.items()}


DEFAULTS: dict[str, Any] = {"float": 0.0, "int": 0, "bool": False, "text": ""}


def _value(name: str, kind: str, value: Any) -> Any:
    if kind == "text":
        if not isinstance(value, str):
            raise InvalidInput(f"{name} must be text")
        if len(value) > MAX_TEXT:
            raise InvalidInput(f"{name} is longer than {MAX_TEXT} characters")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise InvalidInput(f"{name} must be true or false")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidInput(f"{name} must be a number, got {type(value).__name__}")
    # Compared as numbers, never converted first: an integer of 400 digits has no float.
    finite = math.isfinite(value) if isinstance(value, float) else abs(value) <= FLOAT_MAX
    if kind == "int":
        if not finite or value != int(value) or abs(value) > 2**31 - 1:
            raise InvalidInput(f"{name} must be a 32-bit integer")
        return int(value)
    if not finite:
        raise InvalidInput(f"{name} must be a finite number (a 64-bit float)")
    return float(value)


def zero(type_: str) -> dict[str, Any]:
    """The type's stop command: every field zero (a deadman sends it)."""
    return check_fields(type_, {})


__all__ = ["check_fields", "fields_of", "flatten", "nested", "zero"]
