"""The ROS message types of topic inputs and outputs, a control loop's robot and an agent's
targets, without ROS: one entry per type (`types`) saying what its messages hold as ORICF
values both ways (`convert`), their serialized (CDR) form (`cdr`), their definitions
(`definitions`), and input records and output messages made through them (`codec`). The ROS
node (oricf.gateway.ros), recordings (oricf.gateway.recording), the control loop and the
agent's actuation all go through it."""

# The table registers its types' definitions, which cdr.py and recordings read.
from oricf.gateway.topics import types as types
