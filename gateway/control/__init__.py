"""The gateway's local control API, a surface on the operations (oricf.gateway.operations):
`server` (the operations over HTTP on loopback or a Unix socket, bearer tokens, TLS) and
`config` (the `control:` YAML). It imports neither MCP (oricf.gateway.agents) nor the live
view. Importing this package imports nothing. docs/agents.md.
"""
