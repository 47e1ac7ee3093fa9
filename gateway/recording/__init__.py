"""Recording and replaying a pipeline's topics without ROS: MCAP files in rosbag2's layout
(`recorder`, `replay`, `mcap_reader`, `chunks`, `pace`). What a topic message holds and how
it is serialized is the topic codec's (oricf.gateway.topics), shared with the ROS node."""
