"""Route inputs that are not ROS topics, by the input's source key: `url` video (video.py),
`audio` utterances (audio.py), `text` lines (text.py); oricf.gateway.inputs starts them.
Topic inputs belong to the ROS node, or to a replayed recording (replay.py); `product` inputs
to the pipeline itself.
"""
