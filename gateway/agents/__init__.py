"""Agents: ORICF as a Model Context Protocol server, perception free, actuation behind a policy.

`policy` (the `agent:` YAML: targets, message types, bounds, rates, approval, deadman),
`messages` (the message types a target may carry, as flat numeric fields), `actuation`
(checks, rate limits, approval, sending, the deadman), `senders` (ROS topics and text
channels), `approval` (a human's yes or no on a text channel), `audit` (JSON lines and
counters of every tool call), `mcp_server` (the tools on the `mcp` SDK), `resources` (data
products and frames as resources, with update notifications), `stdio` (the SDK's stdio
transport, answering malformed messages), `http` (streamable HTTP: tokens, TLS), `host` (a
pipeline run in the same process), `main` (`oricf mcp`).
docs/agents.md.
Importing this package imports nothing.
"""
