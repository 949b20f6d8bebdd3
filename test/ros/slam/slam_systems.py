"""What the SLAM rostests (test/ros/slam_*.test) know of each system: the names its nodes run
under, its topics, message types, frames and body-frame conventions, its loop-closure path and the
clock its poses are stamped on. Shared by the tester (the camera driver and the checks) and the
stand-ins (slam_stand_in.py), which take the real systems' node names and topics.

Node names, as each system's own launch files start it:
  ORB-SLAM2 (orb_slam2_ros, RGB-D)       /orb_slam2_rgbd            -> /orb_slam2_rgbd/pose
  ORB-SLAM3 (orb_slam3_ros, RGB-D)       /orb_slam3                 -> /orb_slam3/camera_pose
  RTAB-Map (rtabmap_ros rtabmap.launch)  /rtabmap/rgbd_odometry     -> tf odom -> base_link
                                         /rtabmap/rtabmap           -> tf map -> odom, /rtabmap/mapPath
  VINS-Fusion                            /vins_estimator            -> /vins_estimator/odometry
                                         /loop_fusion               -> /loop_fusion/pose_graph_path
"""
import math
import os
import sys

import numpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_poses import compose, inverse, slerp, yaw  # noqa: E402  (the stand-ins use compose from here)

OPTICAL_FROM_X_FORWARD = numpy.array([-0.5, 0.5, -0.5, 0.5])  # x-forward frame <- optical frame

# Per system: the node of ours (its launch file's default name), the stand-ins (node name, role),
# inputs, the optical frame, the pose stream and its frames, the fixed chain from the body frame
# to the optical frame (parent, child, translation, rotation), the loop-closure path.
CONVENTIONS = {
    'orb_slam2': dict(ours='/orb_slam2_view_selection', stand_ins=[('/orb_slam2_rgbd', 'orb_slam2')],
                      image='/camera/rgb/image_raw', info='/camera/rgb/camera_info',
                      depth='/camera/depth_registered/image_raw', optical='camera_rgb_optical_frame',
                      pose=('/orb_slam2_rgbd/pose', 'pose_stamped', 'map', 'camera_link'),
                      chain=[('camera_link', 'camera_rgb_frame', (0.0, -0.045, 0.0), (0, 0, 0, 1)),
                             ('camera_rgb_frame', 'camera_rgb_optical_frame', (0, 0, 0), OPTICAL_FROM_X_FORWARD)],
                      path=None),
    'orb_slam3': dict(ours='/orb_slam3_view_selection', stand_ins=[('/orb_slam3', 'orb_slam3')],
                      image='/camera/rgb/image_raw', info='/camera/rgb/camera_info',
                      depth='/camera/depth_registered/image_raw', optical='camera',
                      pose=('/orb_slam3/camera_pose', 'pose_stamped', 'world', 'camera'), chain=[], path=None),
    'rtabmap': dict(ours='/rtabmap_view_selection',
                    stand_ins=[('/rtabmap/rgbd_odometry', 'rtabmap_odometry'), ('/rtabmap/rtabmap', 'rtabmap')],
                    image='/camera/rgb/image_rect_color', info='/camera/rgb/camera_info',
                    depth='/camera/depth_registered/image_raw', optical='camera_rgb_optical_frame',
                    pose=('tf', 'tf', 'map', 'base_link'),
                    chain=[('base_link', 'camera_link', (0.1, 0.0, 0.3), (0, 0, 0, 1)),
                           ('camera_link', 'camera_rgb_optical_frame', (0.0, -0.045, 0.0), OPTICAL_FROM_X_FORWARD)],
                    path='/rtabmap/mapPath'),
    'vins_fusion': dict(ours='/vins_view_selection',
                        stand_ins=[('/vins_estimator', 'vins_estimator'), ('/loop_fusion', 'loop_fusion')],
                        image='/camera/color/image_raw', info='/camera/color/camera_info',
                        depth='/camera/aligned_depth_to_color/image_raw', optical='camera_color_optical_frame',
                        pose=('/vins_estimator/odometry', 'odometry', 'world', 'body'),
                        # IMU body: x forward; the camera 2 cm beside it, looking forward.
                        chain=[('body', 'camera_color_optical_frame', (0.02, 0.01, 0.0), OPTICAL_FROM_X_FORWARD)],
                        path='/loop_fusion/pose_graph_path'),
}

TRUTH_TOPIC = '/stand_in/truth'            # the optical frame's true pose at each frame, before its image
CLOSE_LOOP_TOPIC = '/stand_in/close_loop'  # std_msgs/Empty: the systems with a path publish it now

RTABMAP_NODE_EVERY = 30      # RTAB-Map adds a map node at 1 Hz (Rtabmap/DetectionRate): every 30th frame
VINS_RATE = 15.0             # [Hz] VINS' odometry, stamped by its own camera ...
VINS_CLOCK_OFFSET = 0.013    # [s] ... on a clock 13 ms off the RGB-D camera's
VINS_KEYFRAME_EVERY = 4      # a VINS keyframe (a pose of pose_graph_path) every 4th of its frames
ORB_SLAM_LATENCY = 0.03      # [s, wall] tracking time before ORB-SLAM publishes a frame's pose


def interpolate(samples, t):
    """The pose at t [s] between the (stamp [s], (t, q)) samples around it (ascending), or None."""
    for (ta, a), (tb, b) in zip(samples, samples[1:]):
        if ta <= t <= tb:
            s = 0.0 if tb == ta else (t - ta) / (tb - ta)
            return a[0] + s * (b[0] - a[0]), slerp(a[1], b[1], s)
    return None


def body_in_optical(convention):
    """optical <- body: the inverse of the chain body -> ... -> optical."""
    optical_in_body = (numpy.zeros(3), numpy.array([0.0, 0.0, 0.0, 1.0]))
    for _, _, t, q in convention['chain']:
        optical_in_body = compose(optical_in_body, (numpy.array(t, float), numpy.array(q, float)))
    return inverse(optical_in_body)


def drift(dt):
    """The drift of the odometry of the systems with a loop-closure path, dt [s] after the start:
    4 cm/s and 2 deg/s in the world, until the path corrects it."""
    return numpy.array([0.04 * dt, 0.0, 0.02 * dt]), yaw(math.radians(2.0 * dt))
