"""The ROS message types a topic input or output may name, and the record field each input
type fills (checked against `from` and templates when a pipeline loads)."""

from __future__ import annotations

from typing import Literal

InputType = Literal["sensor_msgs/Image", "sensor_msgs/CompressedImage", "std_msgs/String",
                    "std_msgs/Int16MultiArray", "std_msgs/Int32"]
OutputType = Literal["std_msgs/Int32", "std_msgs/String", "sensor_msgs/Image",
                     "std_msgs/Int16MultiArray", "vision_msgs/Detection2DArray"]
INPUT_FIELDS: dict[str, str] = {
    "sensor_msgs/Image": "image", "sensor_msgs/CompressedImage": "image",
    "std_msgs/String": "text", "std_msgs/Int16MultiArray": "audio", "std_msgs/Int32": "value",
}
# Camera inputs: newest frame only, sensor_data QoS.
IMAGE_INPUTS = frozenset(t for t, f in INPUT_FIELDS.items() if f == "image")
