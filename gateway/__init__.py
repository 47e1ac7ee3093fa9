"""The gateway: inputs -> model services -> outputs, wired by a pipeline YAML.

Layers, each importing only those below it (pyproject's import contracts check them; `|`
siblings import nothing of each other):

- `shells/`: how a gateway runs: `main` (`oricf gateway`) picks `ros` (a ROS 2 lifecycle
  node, `ros_node`) or `without_ros`; `embedded` runs one inside `oricf mcp` (`mcp`).
- `host/` (the `Gateway` lifecycle: configure, activate, deactivate, cleanup; what starts
  beside a running pipeline, `surfaces`) | `ros/` (the rclpy pieces: cameras, publishers, a
  control loop's topics, the agent's topic commands, parameters, /rosout, the DDS profile).
- the surfaces, none importing another: `agents/` (the MCP server) | `api/` (the local
  control API) | `live_view/` (Foxglove); beneath them `operations/` (reads and calls on a
  pipeline, the API's paths) | `recording/` (MCAP record and replay).
- components, found by the core's registries (`components`, from each package's
  COMPONENTS): `sources/`, `sinks/`, `post/`, `methods/`, one module each.
- the core, importing no ROS and no component: `config` (the pipeline YAML, its unions built
  from the registries), `pipeline` (all of it), `route` (input -> method -> post steps ->
  outputs), `worker` (a thread per route), `components` (the declarations, the parts they
  build and the registries), `outlets` and `inputs` (a pipeline's sinks and sources),
  `metrics`, `listeners` (the surfaces' listener settings), `products` (data products),
  `speaking` (barge-in).
- beneath the core: `actuation/` (the `agent:` policy every command passes), `endpoints/`
  (the servers routes call: deadlines, retries, failover), `tracking/`, `control/` (the
  control loop and its input), `topics/` (the ROS message codec: one entry per type),
  `items` (what a source hands a route, and the `Asker` told its outcome), `values`,
  `throttle`; at the bottom `channels/` (text channels).

Importing this package imports nothing. docs/architecture.md walks through it.
"""
