"""What the gateway knows about each method it can call: its gRPC service and the record
fields it reads and adds (checked against the pipeline YAML at load time)."""

from __future__ import annotations

# method -> the gRPC service it belongs to (also the name its health check uses)
SERVICE_OF: dict[str, str] = {
    "Detect": "oricf.v1.Detector",
    "Transcribe": "oricf.v1.SpeechRecognizer",
    "Generate": "oricf.v1.LanguageModel",
}
# The record fields each input type and each method adds (checked against `from`, templates).
INPUT_FIELDS: dict[str, str] = {
    "sensor_msgs/Image": "image", "sensor_msgs/CompressedImage": "image",
    "std_msgs/String": "text", "std_msgs/Int16MultiArray": "audio", "std_msgs/Int32": "value",
}
# Camera inputs: newest frame only, sensor_data QoS.
IMAGE_INPUTS = frozenset(t for t, f in INPUT_FIELDS.items() if f == "image")
METHOD_FIELDS: dict[str, tuple[str, ...]] = {
    "Detect": ("detections", "counts", "annotated"),
    "Transcribe": ("transcript", "duration_s"),
    "Generate": ("answer",),
}
# Call keys that belong to one method only.
METHOD_KEYS: dict[str, tuple[str, ...]] = {
    "Detect": ("labels", "min_score", "annotate"),
    "Transcribe": ("language",),
    "Generate": ("prompt", "max_tokens", "temperature", "stop", "context"),
}
