"""The gateway's local control API, a surface on the operations (oricf.gateway.operations):
`server` (the operations over HTTP on loopback or a Unix socket, bearer tokens, TLS); its
settings, the pipeline's `control:` key, are oricf.gateway.listeners'. It imports neither MCP
(oricf.gateway.agents) nor the live view. Importing this package imports nothing.
docs/agents.md.
"""
