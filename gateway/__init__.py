"""The ROS 2 gateway: topics -> model services -> topics, wired by a pipeline YAML.

Pure core (no ROS import): config (the YAML schema), values, cdr (camera frames read from
their serialized bytes), calls, post, products, endpoints (deadlines, failover), worker,
route, pipeline. The ROS shell: node, camera (camera routes' receive threads) and convert
(rclpy and message types), roslog (the log on /rosout), rosparams (the node's parameters),
main (`oricf gateway`, `ros2 run oricf_gateway gateway`). Importing this package imports
nothing.
"""
