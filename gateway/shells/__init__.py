"""How a gateway runs: each shell builds a Gateway (oricf.gateway.host) and runs its
lifecycle, adding only what is its own. `main` is `oricf gateway`, which picks `ros` (spins
the ROS 2 node of `ros_node`: topic subscriptions and publishers) or `without_ros` (a
replayed recording too); `embedded` runs a gateway inside `oricf mcp` (`mcp`).
"""
