"""Multi-object tracking and what is measured over tracks.

`kalman` is the motion model of one box, `bytetrack` associates each frame's detections
with tracks (ByteTrack: high-score detections first, then low-score ones for tracks that
were just seen), `geometry` holds the zone and line tests, and `measures` turns tracks over
time into numbers (tracks now, unique tracks in a window, zone entries, exits and dwell,
line crossings). The gateway's post steps (`track`, `count_tracks`, `seen_tracks`, `zone`,
`line`) wrap them. Nothing here imports ROS or the network.
"""
