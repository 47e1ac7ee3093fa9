"""The gateway: inputs -> model services -> outputs, wired by a pipeline YAML.

The core, at this level, imports no ROS: `config` (the pipeline YAML), `values` (frames,
audio clips, records), `products` (data products), `endpoints` (deadlines, retries,
failover; `replicas`), `route` (input -> method -> post steps -> outputs), `worker` (a
thread per route), `pipeline` (all of it), `metrics`, `throttle`. Around it, a package per
concern: `methods/` (one module per method: Detect, Transcribe, Generate, Infer), `post/`
(one module per post step), `sources/` and `sinks/` (inputs and outputs that are no ROS
topics), `text_channels` (the line-based TCP text server), `recording/` (MCAP record and
replay, CDR, message definitions), `ros/` (the rclpy node, cameras, parameters, /rosout,
the DDS profile). `main` is `oricf gateway`; `without_ros` runs a pipeline with no topics.
Importing this package imports nothing. docs/architecture.md walks through it.
"""
