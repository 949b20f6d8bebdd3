"""view_selection's Python side: the COLMAP project the live hand-off keeps, the pair stream's
consumer, and the evaluation maths. The executables in scripts/ are thin layers over it.

  view_selection.geometry     rotations, quaternions, camera centres (numpy)
  view_selection.keyframes    a keyframe as the node names it (message or selection.json)
  view_selection.colmap       COLMAP 3.8: its database, its sparse model, its commands, a project
  view_selection.live         the pair stream's consumer and colmap_bridge's ROS node
  view_selection.evaluation   trajectory alignment (ATE) and TUM-layout reading

Only view_selection.live.bridge imports rospy; everything else runs without a ROS master.
The generated messages (view_selection.msg, view_selection.srv) share this package name;
catkin's devel and install spaces join the two.
"""
