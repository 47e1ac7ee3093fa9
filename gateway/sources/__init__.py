"""Route inputs, one module per input key, each declaring `COMPONENT = SourceKind(...)`
(oricf.gateway.components) and listed in COMPONENTS below: `url` video (video.py), `audio`
utterances (audio.py), `text` lines (text.py), `control` a control loop (control.py);
oricf.gateway.inputs starts them. `topic` inputs belong to the ROS node, or to a replayed
recording (replay.py); `product` inputs to the pipeline itself.

A declaration module holds only the input's schema and its declaration, so that loading the
pipeline schema imports no device, stream or codec: what runs an input (video_source.py,
audio_source.py, and the helpers they use: mjpeg.py, http_stream.py, audio_device.py,
wav.py) is imported by the declaration's `open` when a pipeline starts one. Adding an input
is its module and one line here.
"""

COMPONENTS = (
    "audio",
    "control",
    "product",
    "text",
    "topic",
    "video",
)
