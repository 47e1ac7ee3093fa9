"""Agents: ORICF as a Model Context Protocol server, a surface on the operations
(oricf.gateway.operations), commands through the actuation policy (oricf.gateway.actuation).

`mcp_server` (the tools on the `mcp` SDK), `resources` (data products and frames as
resources, with update notifications), `stdio` (the SDK's stdio transport, answering
malformed messages), `http` (streamable HTTP: tokens, TLS). `oricf mcp` itself is a shell
(oricf.gateway.shells.mcp): a gateway in this process, or one that runs, through the control
API. It imports neither the control API (oricf.gateway.api) nor the live view.
docs/agents.md.
Importing this package imports nothing.
"""
