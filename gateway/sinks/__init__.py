"""Route outputs, one module per output key, each declaring `COMPONENT = SinkKind(...)`
(oricf.gateway.components): `topic` ROS topics (topic.py, sent by the ROS node or a
recording), `product` data products (product.py, kept by the pipeline), `jsonl` JSON lines
(jsonl.py), `text` lines on standard output or a text channel (text.py), `frames` image and
video files (frames.py), `audio` speech on a speaker (speaker.py), `wav` speech into WAV
files (wav.py). oricf.gateway.outlets.Outlets hands each output to its sink."""
