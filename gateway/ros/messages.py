"""Topic messages as rclpy's message objects: the class of a type, and a message filled from
its fields by name, the form in which the table of types (oricf.gateway.topics) gives every
message the gateway writes (recordings serialize the same fields without ROS). Every
publisher of the node fills its messages here: topic outputs, a control loop's actions and
an agent's commands.

A message package is imported when a pipeline first names one of its types; a package that
is not installed (vision_msgs comes with a robot's ROS, not with the PyPI wheels) refuses the
pipeline at start, saying what to install.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from oricf.errors import ConfigError
from oricf.gateway.topics import cdr, codec


def message_type(type_: str) -> Any:
    """The rclpy message class of a type, "package/Type" (ConfigError naming what to
    install if its package cannot be imported)."""
    package, _, name = type_.partition("/")
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except ImportError as exc:
        raise ConfigError(f"{type_} needs the ROS package {package}, which cannot be "
                          f"imported here ({exc}): install the {package} package of your ROS "
                          f"distribution (e.g. apt install ros-jazzy-"
                          f"{package.replace('_', '-')}) and source its setup") from None


def to_message(type_: str, value: Any, header: cdr.Stamp | None = None) -> Any:
    """A value -> the message of the given type (TypeError or ValueError for a value that
    does not fit it)."""
    return filled(message_type(type_), codec.message_fields(type_, value, header))


def filled(cls: Any, fields: Mapping[str, Any]) -> Any:
    """A message of class `cls` with the given fields (nested messages as mappings, sequences
    of messages as lists of them); the fields left out keep their defaults. ValueError for a
    value that does not fit its field."""
    msg = cls()
    types = cls.get_fields_and_field_types()
    for name, value in fields.items():
        if isinstance(value, Mapping):
            value = filled(type(getattr(msg, name)), value)
        elif isinstance(value, list) and value and isinstance(value[0], Mapping):
            item_cls = message_type(types[name].removeprefix("sequence<").removesuffix(">"))
            value = [filled(item_cls, item) for item in value]
        try:
            setattr(msg, name, value)
        except AssertionError as exc:  # rclpy's setters assert the type and the range
            raise ValueError(f"{cls.__name__}.{name}: {exc}") from None
    return msg
