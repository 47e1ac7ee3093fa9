"""Route outputs, one module per output key, each declaring `COMPONENT = SinkKind(...)`
(oricf.gateway.components) and listed in COMPONENTS below: `topic` ROS topics (topic.py,
sent by the ROS node or a recording), `product` data products (product.py, kept by the
pipeline), `jsonl` JSON lines (jsonl.py), `text` lines on standard output or a text channel
(text.py), `frames` image and video files (frames.py), `audio` speech on a speaker
(speaker.py; played by speaker_sink.py on speaker_device.py, imported when a pipeline opens
it), `wav` speech into WAV files (wav.py). oricf.gateway.outlets.Outlets hands each output
to its sink. Adding an output is its module and one line here."""

COMPONENTS = (
    "frames",
    "jsonl",
    "product",
    "speaker",
    "text",
    "topic",
    "wav",
)
