"""The gateway: inputs -> model services -> outputs, wired by a pipeline YAML.

The core, at this level, imports no ROS: `config` (the pipeline YAML), `values` (frames,
audio clips, records), `products` (data products), `route` (input -> method -> post steps ->
outputs), `worker` (a thread per route), `pipeline` (all of it), `metrics`, `throttle`,
`speaking` (whether a speaker plays; barge-in), and `text_channels` with `text_clients` (the
line-based TCP text server). Around it, a package per concern: `endpoints/` (the servers
routes call over gRPC or the OpenAI API: deadlines, retries, failover), `methods/` (one
module per method: Detect, Transcribe, Generate, Infer, Synthesize), `post/` (one module per
post step), `tracking/` (multi-object tracking and what is measured over tracks), `sources/`
and `sinks/` (inputs and outputs that are no ROS topics), `recording/` (MCAP record and
replay, CDR, message definitions), `ros/` (the rclpy node, cameras, publishers, parameters,
/rosout, the DDS profile), `control/` (the local control API: the pipeline's state and calls
over HTTP on loopback or a Unix socket), `agents/` (`oricf mcp`: the MCP server and the
`agent:` policy that commands pass). `main` is `oricf gateway`; `without_ros` runs a
pipeline with no topics.
Importing this package imports nothing. docs/architecture.md walks through it.
"""
