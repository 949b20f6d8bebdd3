"""The live hand-off's consumer side: the pair stream (stream.py, no ROS) and colmap_bridge's
ROS node (bridge.py)."""
