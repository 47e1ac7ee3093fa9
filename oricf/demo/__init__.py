"""`oricf demo`: the reference pipeline end to end on one machine (docs in README.md).

    main  the command line: which deployment, camera and questions
    run   the sequence: launch, connect, start the camera, ask each question, report
    node  the demo's ROS 2 node: the camera and the questions out, the gateway's outputs in

The demo is an application on top of the launcher (oricf.launch) and the gateway's video
sources; only `node` imports rclpy.
"""
