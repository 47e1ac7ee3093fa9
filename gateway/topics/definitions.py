"""The ROS 2 message definitions of the topic types the gateway reads and writes, in
rosbag2's `ros2msg` form, without ROS: an MCAP recording names each channel's type and
carries its complete definition, so tools without the message packages can decode it.

The complete definition of a type is its .msg text, then that of every type it uses, each
after a line of 80 `=` and a line `MSG: package/Type` (rosbag2's own layout). The text comes
from the installed ROS packages' share/PACKAGE/msg/TYPE.msg when they are found (the PyPI
wheels install them under the virtual environment, apt ROS under /opt/ros/DISTRO, named by
AMENT_PREFIX_PATH), comments and all as rosbag2 writes them, else from DEFINITIONS below:
the same fields without the comments (a test compares the two, so the table cannot drift).
The same table lays out the messages cdr.py writes (`layout`). It holds the types that topic
types use; the topic types' own definitions are their entries' (oricf.gateway.topics.types,
which this package imports first, adds them).
"""

from __future__ import annotations

import functools
import os
import sys
from dataclasses import dataclass
from pathlib import Path

# The types that topic types' fields use; each topic type's own definition is its entry's in
# oricf.gateway.topics.types, which adds it here (`register`).
DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/MultiArrayDimension": "string label\nuint32 size\nuint32 stride\n",
    "std_msgs/MultiArrayLayout": "MultiArrayDimension[] dim\nuint32 data_offset\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "trajectory_msgs/JointTrajectoryPoint": (
        "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\n"
        "float64[] effort\nbuiltin_interfaces/Duration time_from_start\n"),
    # vision_msgs 4.1.1 (ROS 2 Jazzy); no wheel installs these, a robot's apt does.
    "vision_msgs/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/ObjectHypothesisWithPose": ("ObjectHypothesis hypothesis\n"
                                             "geometry_msgs/PoseWithCovariance pose\n"),
    "vision_msgs/Detection2D": ("std_msgs/Header header\nObjectHypothesisWithPose[] results\n"
                                "BoundingBox2D bbox\nstring id\n"),
}
SEPARATOR = "=" * 80
PRIMITIVES = frozenset({"bool", "byte", "char", "float32", "float64", "int8", "uint8",
                        "int16", "uint16", "int32", "uint32", "int64", "uint64", "string",
                        "wstring"})


def schema_name(type_: str) -> str:
    """"sensor_msgs/Image" -> "sensor_msgs/msg/Image", the name rosbag2 gives a schema."""
    package, _, name = type_.partition("/")
    return f"{package}/msg/{name}"


def type_name(schema: str) -> str:
    """A schema or type name in either form -> "package/Type" (ROS 1 style names pass)."""
    parts = schema.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) >= 2 else schema


def share_dirs() -> list[Path]:
    """Where installed ROS packages keep their share/ folders: AMENT_PREFIX_PATH, then this
    Python's prefix (the PyPI wheels)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [Path(prefix) / "share" for prefix in [*prefixes, sys.prefix]]


def installed_definition(type_: str) -> str | None:
    """The installed .msg text of a type, or None if no installed package has it."""
    package, _, name = type_.partition("/")
    for share in share_dirs():
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    return None


def fields_only(text: str) -> str:
    """A .msg text without comments, blank lines and alignment spaces (for comparing)."""
    lines = (" ".join(line.split("#", 1)[0].split()) for line in text.splitlines())
    return "".join(f"{line}\n" for line in lines if line)


def _full_type(package: str, field_type: str) -> str:
    """A field's type as "package/Type" (a bare name is of the containing package)."""
    if field_type in PRIMITIVES or "/" in field_type:
        return field_type
    return f"{package}/{field_type}"


def _used_types(type_: str, text: str) -> list[str]:
    """The message types a definition's fields use, as "package/Type", in order."""
    package = type_.partition("/")[0]
    used = []
    for line in fields_only(text).splitlines():
        field_type = line.split()[0].split("[")[0].split("<=")[0]
        if field_type not in PRIMITIVES:  # (constants are always of primitive types)
            used.append(_full_type(package, field_type))
    return used


@dataclass(frozen=True)
class Field:
    """One field of a message: `count` None for a single value, -1 for a sequence (T[]),
    N for an array (T[N]); `default` as the definition gives it, else None."""

    name: str
    type: str  # a primitive, or "package/Type"
    count: int | None
    default: float | None


def layout(type_: str) -> tuple[Field, ...]:
    """The fields of a type of DEFINITIONS, in order (KeyError for another type)."""
    return _layout(type_, DEFINITIONS[type_])


@functools.cache
def _layout(type_: str, text: str) -> tuple[Field, ...]:
    package = type_.partition("/")[0]
    fields = []
    for line in text.splitlines():
        kind, name, *default = line.split()
        base, bracket, size = kind.partition("[")
        count = None if not bracket else int(size[:-1] or -1)
        fields.append(Field(name, _full_type(package, base), count,
                            float(default[0]) if default else None))
    return tuple(fields)


def primitive_fields(type_: str, prefix: str = "") -> dict[str, str]:
    """The single primitive fields of a type of DEFINITIONS by dotted name, nested messages
    walked ({"linear.x": "float64", ...} for geometry_msgs/Twist); arrays left out."""
    fields: dict[str, str] = {}
    for field in layout(type_):
        if field.count is not None:
            continue
        if field.type in PRIMITIVES:
            fields[prefix + field.name] = field.type
        else:
            fields.update(primitive_fields(field.type, f"{prefix}{field.name}."))
    return fields


@functools.cache
def definition(type_: str) -> str:
    """One type's .msg text: the installed file's if it has the table's fields (so the schema
    always matches what oricf.gateway.topics.cdr reads and writes), else the table's."""
    installed = installed_definition(type_)
    if installed is not None and fields_only(installed) == DEFINITIONS[type_]:
        return installed
    return DEFINITIONS[type_]


@functools.cache
def complete_definition(type_: str) -> str:
    """The type's definition followed by every type it depends on, once each (ros2msg)."""
    parts = [definition(type_).strip()]
    seen = {type_}
    pending = _used_types(type_, definition(type_))
    while pending:
        used = pending.pop(0)
        if used in seen:
            continue
        seen.add(used)
        text = definition(used)
        parts.append(f"{SEPARATOR}\nMSG: {used}\n{text.strip()}")
        pending.extend(_used_types(used, text))
    return "\n".join(parts) + "\n"
