"""The gateway on ROS 2: the rclpy node (`node`), camera subscriptions on threads of their
own and the frames they lose (`camera`, `frame_loss`), topic publishers (`publishers`),
message conversion (`messages`), the node's parameters (`params`), its log on /rosout
(`rosout`), the Fast DDS profile (`dds`), process settings (`process`), the spin loop
(`spin`) and the agent's commands on topics, as the actuation policy passed them
(`commands`). Only this package imports rclpy; `dds`, `frame_loss` and `process` import no ROS.
"""
