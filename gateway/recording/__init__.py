"""Recording and replaying a pipeline's topics without ROS: MCAP files in rosbag2's layout
(`recorder`, `replay`, `mcap_reader`), the CDR bytes of the topic types (`cdr`), their
message definitions (`definitions`), and what a topic message turns into as a route value
(`topic_values`, shared with the ROS node)."""
