"""The ROS message types the gateway reads or writes, each declared once (TYPES): its name,
its fields (the .msg definition recordings carry and cdr.py lays out), how a message becomes
an ORICF value and a value its message (oricf.gateway.topics.convert), and what may name it:

- `input`: a topic input (`input: {topic, type}`), filling the record field `field`;
- `output`: a topic output (`outputs: [{topic, type, from}]`);
- `state`, `camera`: a control loop's state part or camera (oricf.gateway.control.parts);
- `action`: a control loop's target (oricf.gateway.control.target);
- `command`: an agent's target (oricf.gateway.actuation), its fields checked by kind.

The ROS node (oricf.gateway.ros), recordings (oricf.gateway.recording), the control loop and
the agent's actuation all read this table; the settings that name a type take the list from
it. A new type is one `register(RosType(...))`. No ROS import.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from oricf.errors import InvalidInput
from oricf.gateway.topics import cdr, convert, definitions
from oricf.gateway.topics.convert import Read, Write

Role = Literal["input", "output", "state", "camera", "action", "command"]


@dataclass(frozen=True)
class RosType:
    """One ROS message type. `parse`: for a type taken serialized (camera frames: cheaper
    than rclpy's message, whose pixels it copies), its CDR bytes -> the fields `read` reads.
    `names`: the settings key that names its values (`joints` of a JointState part or a
    JointTrajectory target, `fields` of a Twist target). `depth`: how many messages its
    publisher keeps for a slow subscriber."""

    name: str
    definition: str
    roles: frozenset[Role]
    read: Read | None = None
    write: Write | None = None
    field: str | None = None
    parse: Callable[[bytes], Any] | None = None
    names: Literal["joints", "fields"] | None = None
    depth: int = 10

    @property
    def frames(self) -> bool:
        """Its messages are camera frames: taken serialized, newest only (sensor_data QoS),
        each on its route's own thread (oricf.gateway.ros.camera)."""
        return self.parse is not None

    def decoded(self, message: Any) -> Any:
        """The message as `read` takes it: parsed first if it came serialized."""
        if self.parse is not None and isinstance(message, bytes | bytearray | memoryview):
            return self.parse(bytes(message))
        return message

    def value(self, message: Any) -> Any:
        """A message (decoded, or serialized for a type taken so) -> its value."""
        if self.read is None:
            raise InvalidInput(f"the gateway does not read {self.name}")
        return self.read(self.decoded(message))


TYPES: dict[str, RosType] = {}


def register(entry: RosType) -> None:
    """Adds a type: its entry, and its definition for recordings and cdr.py."""
    TYPES[entry.name] = entry
    definitions.DEFINITIONS[entry.name] = entry.definition


def unregister(name: str) -> None:
    del TYPES[name], definitions.DEFINITIONS[name]


def ros_type(name: str) -> RosType:
    """The entry of a type (InvalidInput for a type the gateway does not read or write)."""
    try:
        return TYPES[name]
    except KeyError:
        raise InvalidInput(f"unsupported message type {name}") from None


def names(role: Role) -> list[str]:
    """The types that may be named as `role`, in the table's order."""
    return [name for name, entry in TYPES.items() if role in entry.roles]


def check(name: str, role: Role, what: str) -> str:
    """`name` if a type of `role`, else ValueError naming those that are (for settings)."""
    if name not in TYPES or role not in TYPES[name].roles:
        raise ValueError(f"{what}: {', '.join(names(role))}")
    return name


# The types settings name by default: a text channel's, a camera's, a control target's.
TEXT, IMAGE, NUMBERS = "std_msgs/String", "sensor_msgs/Image", "std_msgs/Float64MultiArray"
HEADER = "std_msgs/Header header\n"
for _entry in [
    # depth 1: a subscriber that falls behind gets the newest frame, not a backlog
    RosType(IMAGE, HEADER + "uint32 height\nuint32 width\nstring encoding\n"
            "uint8 is_bigendian\nuint32 step\nuint8[] data\n",
            frozenset({"input", "output", "camera"}), convert.image_frame,
            convert.image_fields, "image", cdr.image, depth=1),
    RosType("sensor_msgs/CompressedImage", HEADER + "string format\nuint8[] data\n",
            frozenset({"input", "camera"}), convert.compressed_frame_of,
            convert.compressed_image_fields, "image", cdr.compressed_image, depth=1),
    RosType(TEXT, "string data\n", frozenset({"input", "output", "command"}),
            convert.data, convert.text_fields, "text"),
    RosType("std_msgs/Int16MultiArray", "MultiArrayLayout layout\nint16[] data\n",
            frozenset({"input", "output"}), convert.samples, convert.audio_fields, "audio"),
    RosType("std_msgs/Int32", "int32 data\n", frozenset({"input", "output", "command"}),
            convert.data, convert.int_fields, "value"),
    RosType("vision_msgs/Detection2DArray", HEADER + "Detection2D[] detections\n",
            frozenset({"output"}), write=convert.detection_array_fields),
    RosType("sensor_msgs/JointState", HEADER + "string[] name\nfloat64[] position\n"
            "float64[] velocity\nfloat64[] effort\n", frozenset({"state"}),
            convert.joint_states, names="joints"),
    RosType(NUMBERS, "MultiArrayLayout layout\nfloat64[] data\n",
            frozenset({"state", "action"}), convert.float_array, convert.float_array_fields),
    RosType("trajectory_msgs/JointTrajectory", HEADER + "string[] joint_names\n"
            "JointTrajectoryPoint[] points\n", frozenset({"action"}),
            write=convert.trajectory_fields, names="joints"),
    RosType("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n",
            frozenset({"action", "command"}), write=convert.flat_fields, names="fields"),
    RosType("std_msgs/Float64", "float64 data\n", frozenset({"command"})),
    RosType("std_msgs/Bool", "bool data\n", frozenset({"command"})),
]:
    register(_entry)
