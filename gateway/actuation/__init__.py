"""Actuation: everything that can move the robot goes through here, whichever surface asks
(the MCP tools, the control API).

`policy` (the `agent:` YAML: targets, message types, bounds, rates, approval, deadman),
`messages` (the message types a target may carry, as flat numeric fields), `actuation`
(checks, rate limits, approval, sending, the deadman), `senders` (text channels, and ROS
topics through the sender its caller makes: oricf.gateway.ros.commands), `approval` (a
human's yes or no on a text channel), `audit` (JSON lines and counters of every call).
It imports no surface (agents, control, live_view) and no ROS package (pyproject.toml's
import contracts). docs/agents.md.
Importing this package imports nothing.
"""
