"""The gateway as a component host: one pipeline's parts and their lifecycle (`gateway`:
configure, activate, deactivate, cleanup) and what starts beside a running pipeline
(`surfaces`: the live view, the operations with the agent's actuation, the control API).
The shells (oricf.gateway.shells) run a Gateway under ROS, without ROS, or inside
`oricf mcp`; nothing here imports ROS.
"""
