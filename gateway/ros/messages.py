"""Topic messages as rclpy's message objects: the classes of the topic types, and route
values filled into them from oricf.gateway.topics.codec, the one table of what each type's
messages hold (recordings write the same fields without ROS).

Incoming messages become loaders: conversion runs when the route takes the message, so a
queued message that is dropped is never converted. Camera frames arrive serialized and are
read by the codec (oricf.gateway.topics.cdr); the other inputs arrive as rclpy messages,
read from their `data`.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from oricf.gateway.config import InputConfig
from oricf.gateway.ros import vision
from oricf.gateway.route import Loader
from oricf.gateway.topics import cdr, codec


def message_type(type_: str) -> Any:
    """The rclpy message class of a topic type, "package/Type" (vision_msgs imported only
    when asked for, ConfigError if it cannot be)."""
    package, _, name = type_.partition("/")
    if package == "vision_msgs":
        return getattr(vision.vision_msgs(), name)
    return getattr(importlib.import_module(f"{package}.msg"), name)


def loader(config: InputConfig, msg: Any) -> Loader:
    """One incoming message (not a camera frame) -> the loader of the route's input record."""
    return codec.data_loader(config, msg.data)


def to_message(type_: str, value: Any, header: cdr.Stamp | None = None) -> Any:
    """A route value -> the output message of the given type (TypeError or ValueError for a
    value that does not fit it)."""
    return filled(message_type(type_), codec.message_fields(type_, value, header))


def filled(cls: Any, fields: Mapping[str, Any]) -> Any:
    """A message of class `cls` with the given fields (nested messages as mappings, sequences
    of messages as lists of them); the fields left out keep their defaults."""
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
