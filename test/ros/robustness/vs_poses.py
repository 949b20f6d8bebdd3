"""Rigid motions for the rostests' stand-ins and checks: quaternions (x, y, z, w) as numpy arrays,
poses as (translation, quaternion), the messages that carry them, and a pinhole camera_info. Shared by the corrections,
SLAM and stand-in testers."""
import math

import numpy
from geometry_msgs.msg import PoseStamped, TransformStamped
from sensor_msgs.msg import CameraInfo


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return numpy.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def qconj(q):
    return numpy.array([-q[0], -q[1], -q[2], q[3]])


def rotate(q, v):
    return qmul(qmul(q, numpy.array([v[0], v[1], v[2], 0.0])), qconj(q))[:3]


def compose(a, b):
    """(t, q) of a * b."""
    return a[0] + rotate(a[1], b[0]), qmul(a[1], b[1])


def inverse(a):
    qi = qconj(a[1])
    return -rotate(qi, a[0]), qi


def yaw(angle):
    return numpy.array([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)])


def slerp(a, b, s):
    dot = float(numpy.dot(a, b))
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 0.9995:
        q = a + s * (b - a)
    else:
        theta = math.acos(dot)
        q = (math.sin((1 - s) * theta) * a + math.sin(s * theta) * b) / math.sin(theta)
    return q / numpy.linalg.norm(q)


def pose_msg(t, q, stamp, frame='world'):
    m = PoseStamped()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = t
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = q
    return m


def transform_msg(parent, child, t, q, stamp):
    m = TransformStamped()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, parent, child
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = t
    m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w = q
    return m


def camera_info_msg(stamp, frame, width, height, fx, fy, cx, cy):
    """A pinhole camera without distortion (plumb_bob, D zero), as drivers publish it."""
    info = CameraInfo()
    info.header.stamp, info.header.frame_id = stamp, frame
    info.width, info.height, info.distortion_model = width, height, 'plumb_bob'
    info.D = [0.0] * 5
    info.K = [fx, 0, cx, 0, fy, cy, 0, 0, 1]
    info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    info.P = [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]
    return info
