"""The gateway: inputs -> model services -> outputs, wired by a pipeline YAML.

Layers, each importing only those below it (pyproject's import contracts check them):

- `shells/`: how a gateway runs: `main` (`oricf gateway`) picks `ros` (a ROS 2 node,
  `ros_node`) or `without_ros`; `embedded` runs one inside `oricf mcp` (`mcp`).
- `host/`: the `Gateway` lifecycle (configure, activate, deactivate, cleanup) and what
  starts beside a running pipeline (`surfaces`).
- `ros/` (the rclpy pieces: cameras, publishers, the agent's topic commands, parameters,
  /rosout, the DDS profile) and `recording/` (MCAP record and replay).
- surfaces, none importing another: `control/` (the local control API), `agents/` (the MCP
  server), `live_view/` (Foxglove); they share `operations/` (reads and calls on a pipeline)
  and `actuation/` (the `agent:` policy every command passes).
- components, found by the core's registries (`components`): `sources/`, `methods/`,
  `post/`, `sinks/`, one module each.
- the core, at this level, imports no ROS and no component: `config` (the pipeline YAML,
  its unions built from the registries), `listeners` (the surfaces' listener settings),
  `components` (the registries), `values`, `products` (data products), `route` (input ->
  method -> post steps -> outputs), `worker` (a thread per route), `pipeline` (all of it),
  `outlets` and `inputs` (a pipeline's sinks and sources), `metrics`, `throttle`,
  `speaking` (barge-in); below it `endpoints/` (the servers routes call: deadlines, retries,
  failover), `topics/` (the ROS message codec), `tracking/`, `channels/` (text channels).

Importing this package imports nothing. docs/architecture.md walks through it.
"""
