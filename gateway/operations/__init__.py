"""The operations on a pipeline: what an agent, a dashboard or a script may read and do,
whichever surface carries them (the control API, MCP).

`api` (the operations, their limits and errors: the one interface both sides implement),
`view` (the operations on a pipeline in this process), `client` (the same operations from
another process, over the control API's HTTP: `oricf mcp --attach`), `names` (the check of
a name a caller passes, the same on both sides), `tensors` (tensors as JSON).
It imports no surface (agents, control, live_view) and no ROS package (pyproject.toml's
import contracts). docs/agents.md.
Importing this package imports nothing.
"""
