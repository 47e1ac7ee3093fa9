"""The live view: what a pipeline sees, served over the Foxglove WebSocket protocol, for
Foxglove and Lichtblick to show (docs/live-view.md).

`config` is the pipeline's `foxglove:` key; `messages` turns route values into Foxglove
messages (frames, image annotations, plottable numbers, log lines); `view` feeds them to the
foxglove-sdk server at a capped frame rate, off the routes' threads; `front` is the listener
clients reach: subprotocols, tokens, TLS and limits, relaying to the SDK's server.
"""
