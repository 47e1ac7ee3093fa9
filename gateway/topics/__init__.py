"""The ROS message types of topic inputs and outputs, without ROS: one entry per type saying
how its messages become route values and values become its messages (`codec`), their
serialized (CDR) form (`cdr`) and their definitions (`definitions`). The ROS node
(oricf.gateway.ros) and recordings (oricf.gateway.recording) both go through it."""
