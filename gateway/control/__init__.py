"""The gateway's local control API: what an agent, a dashboard or a script may read and do.

`api` (the operations, their limits and errors: the one interface both sides implement),
`view` (the operations on a pipeline in this process), `names` (the check of a name a
caller passes, the same on both sides), `tensors` (tensors as JSON),
`config` (the `control:` YAML),
`server` (the operations over HTTP on loopback or a Unix socket, bearer tokens, TLS),
`client` (the same operations from another process: `oricf mcp --attach`).
Importing this package imports nothing. docs/agents.md.
"""
