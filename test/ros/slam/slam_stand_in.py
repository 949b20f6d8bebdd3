#!/usr/bin/env python3
"""A stand-in for one node of a SLAM system (test/ros/slam_*.test): it runs under the real
node's name and publishes the real node's topics, types, frames and clock, from the true pose of
each frame that the tester sends on /stand_in/truth before the frame's image (where the real
system would track the image). ~role (slam_systems.py has the table):

  orb_slam2         /orb_slam2_rgbd/pose: PoseStamped in map of camera_link, 30 ms after the frame
  orb_slam3         /orb_slam3/camera_pose: PoseStamped in world of the optical frame, 30 ms after
  rtabmap_odometry  tf odom -> base_link at each frame (drifting)
  rtabmap           tf map -> odom at each frame; /rtabmap/mapPath (latched): its map nodes only, one
                    a second (every 30th image it received), republished as each one is added (as
                    RTAB-Map republishes it with every map update): at the odometry's drifting
                    poses until /stand_in/close_loop, which adds the last image as the loop's node;
                    then at the true poses up to it and, after it, the odometry's corrected by
                    map -> odom, which from then on is the loop's correction, as RTAB-Map's is
  vins_estimator    /vins_estimator/odometry: Odometry in world of body (drifting) at 15 Hz on a
                    clock of its own (13 ms off the frames'), each pose once the frames around it
                    were tracked
  loop_fusion       /loop_fusion/pose_graph_path (latched): its keyframes only, every 4th of VINS'
                    own stamps, republished as each one is added (as loop_fusion's addKeyFrame
                    does): at the VIO's drifting poses until /stand_in/close_loop, then at the true
                    ones up to the loop and the VIO's corrected by the loop's drift after it

~convention names the system. The drifting systems' odometry drifts 4 cm/s and 2 deg/s all along,
as an odometry does after a loop closure too: VINS' /vins_estimator/odometry is not corrected by
loop_fusion, RTAB-Map's odom -> base_link is corrected by map -> odom.
"""
import os
import sys
import threading

import rospy
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import Image
from std_msgs.msg import Empty
from tf2_msgs.msg import TFMessage

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import slam_systems as systems  # noqa: E402


IDENTITY = (systems.numpy.zeros(3), systems.numpy.array([0.0, 0.0, 0.0, 1.0]))  # translation, xyzw


def stamp_of(seconds):
    ns = int(round(seconds * 1e9))
    return rospy.Time(ns // 1000000000, ns % 1000000000)


def pose_msg(pose, stamp, frame):
    m = PoseStamped()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = pose[0]
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = pose[1]
    return m


def transform(parent, child, pose, stamp):
    m = TransformStamped()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, parent, child
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = pose[0]
    m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w = pose[1]
    return m


class StandIn:
    def __init__(self):
        self.role = rospy.get_param('~role')
        self.c = systems.CONVENTIONS[rospy.get_param('~convention')]
        self.topic, self.kind, self.world, self.body_frame = self.c['pose']
        self.to_body = systems.body_in_optical(self.c)
        self.lock = threading.Lock()
        self.truth = []  # (stamp [s], body pose), ascending
        self.t0 = None
        self.next_odometry = 0  # index of the next VINS stamp to publish
        self.drifting = self.c['path'] is not None
        # rtabmap and loop_fusion: the stamp of the keyframe (map node) that closed the loop (None
        # before) and the odometry's correction from then on (RTAB-Map's map -> odom)
        self.loop_at, self.loop_correction = None, None
        # rtabmap: its map nodes' stamps (the images it took as nodes), how many of them its path
        # had when last published
        self.nodes, self.nodes_published = [], 0
        # loop_fusion: the keyframes added to its path so far (VINS stamp indices)
        self.keyframes_added = 0
        if self.role in ('orb_slam2', 'orb_slam3'):
            self.pub = rospy.Publisher(self.topic, PoseStamped, queue_size=100)
        elif self.role == 'vins_estimator':
            self.pub = rospy.Publisher(self.topic, Odometry, queue_size=100)
        elif self.role in ('rtabmap_odometry', 'rtabmap'):
            self.pub = rospy.Publisher('/tf', TFMessage, queue_size=100)
        self.image_stamps = []
        if self.role == 'rtabmap':  # RTAB-Map's map nodes are frames it received
            rospy.Subscriber(self.c['image'], Image, self.on_image, queue_size=100)
        if self.role in ('rtabmap', 'loop_fusion'):
            self.path_pub = rospy.Publisher(self.c['path'], Path, queue_size=1, latch=True)
            rospy.Subscriber(systems.CLOSE_LOOP_TOPIC, Empty, self.on_close_loop)
        rospy.Subscriber(systems.TRUTH_TOPIC, PoseStamped, self.on_truth, queue_size=1000)

    def on_image(self, msg):
        with self.lock:
            self.image_stamps.append(msg.header.stamp.to_sec())
            if (len(self.image_stamps) - 1) % systems.RTABMAP_NODE_EVERY == 0:
                self.nodes.append(self.image_stamps[-1])
        self.publish_map_path()

    def graph_pose(self, t, truth):
        """The system's pose of its own keyframe (RTAB-Map's map node) at t, under the lock: the
        odometry's before the loop closed; after, the truth up to the loop's keyframe and the
        odometry corrected by the loop's drift after it."""
        body = systems.interpolate(truth, t)
        if self.loop_at is not None and t <= self.loop_at:
            return body
        odometry = self.odometry_of(t, body)
        return odometry if self.loop_at is None else systems.compose(self.loop_correction, odometry)

    def close_loop_at(self, t):
        """Under the lock: the keyframe at t closes the loop, the odometry's drift up to it known
        from then on."""
        self.loop_at = t
        self.loop_correction = systems.inverse(systems.drift(t - self.t0))

    def publish_path(self, poses):
        """The loop-closure path of `poses` ((stamp, pose) of the system's keyframes); returns how
        many."""
        path = Path()
        path.header.stamp, path.header.frame_id = rospy.Time.now(), self.world
        path.poses = [pose_msg(pose, stamp_of(t), self.world) for t, pose in poses]
        self.path_pub.publish(path)
        return len(path.poses)

    def publish_map_path(self, force=False):
        """mapPath with the map nodes whose true pose has come (the images and the truth come on
        two connections), when that is more of them than last time (or `force`)."""
        with self.lock:
            if not self.truth:
                return
            truth = list(self.truth)
            nodes = [t for t in self.nodes if t <= truth[-1][0]]
            if len(nodes) <= self.nodes_published and not force:
                return
            self.nodes_published = len(nodes)
            poses = [(t, self.graph_pose(t, truth)) for t in nodes]
        return self.publish_path(poses)

    def body_at(self, optical):
        return systems.compose(optical, self.to_body)

    def odometry_of(self, t, body):
        """What the system's odometry says at t: the truth, drifted when the system drifts."""
        return systems.compose(systems.drift(t - self.t0), body) if self.drifting else body

    def on_truth(self, msg):
        p, q = msg.pose.position, msg.pose.orientation
        optical = (systems.numpy.array([p.x, p.y, p.z]), systems.numpy.array([q.x, q.y, q.z, q.w]))
        t = msg.header.stamp.to_sec()
        body = self.body_at(optical)
        with self.lock:
            if self.t0 is None:
                self.t0 = t
            self.truth.append((t, body))
        stamp = msg.header.stamp
        if self.role in ('orb_slam2', 'orb_slam3'):
            out = pose_msg(self.odometry_of(t, body), stamp, self.world)
            rospy.Timer(rospy.Duration(systems.ORB_SLAM_LATENCY), lambda _: self.pub.publish(out), oneshot=True)
        elif self.role == 'rtabmap_odometry':
            self.pub.publish(TFMessage(transforms=[transform('odom', self.body_frame, self.odometry_of(t, body),
                                                             stamp)]))
        elif self.role == 'rtabmap':
            with self.lock:
                map_odom = self.loop_correction if self.loop_at is not None else IDENTITY
            self.pub.publish(TFMessage(transforms=[transform(self.world, 'odom', map_odom, stamp)]))
            self.publish_map_path()  # a node whose image came before its truth
        elif self.role == 'vins_estimator':
            self.publish_vins_odometry()
        elif self.role == 'loop_fusion':
            self.add_vins_keyframes()

    def vins_stamp(self, n):
        return self.t0 + systems.VINS_CLOCK_OFFSET + n / systems.VINS_RATE

    def publish_vins_odometry(self):
        """Every VINS stamp the frames so far surround, once: its own camera's frames, tracked."""
        while True:
            with self.lock:
                t = self.vins_stamp(self.next_odometry)
                if t > self.truth[-1][0]:
                    return
                body = systems.interpolate(self.truth, t)
                self.next_odometry += 1
            pose = self.odometry_of(t, body)
            m = Odometry()
            m.header.stamp, m.header.frame_id = stamp_of(t), self.world
            m.child_frame_id = self.body_frame
            m.pose.pose = pose_msg(pose, m.header.stamp, self.world).pose
            self.pub.publish(m)

    def add_vins_keyframes(self):
        """Every VINS keyframe stamp the frames so far surround, added; the path published again
        when one was."""
        with self.lock:
            added = False
            while self.vins_stamp(self.keyframes_added * systems.VINS_KEYFRAME_EVERY) <= self.truth[-1][0]:
                self.keyframes_added += 1
                added = True
        if added:
            self.publish_pose_graph_path()

    def publish_pose_graph_path(self):
        with self.lock:
            truth = list(self.truth)
            stamps = [self.vins_stamp(n * systems.VINS_KEYFRAME_EVERY) for n in range(self.keyframes_added)]
            poses = [(t, self.graph_pose(t, truth)) for t in stamps]
        self.publish_path(poses)

    def on_close_loop(self, _):
        if self.role == 'loop_fusion':
            return self.close_vins_loop()
        # The last image is the loop's node. The frames that follow are in map at the corrected
        # pose: the loop node's true pose times its odometry pose^-1, which undoes the drift up to it.
        with self.lock:
            if self.nodes[-1] != self.image_stamps[-1]:
                self.nodes.append(self.image_stamps[-1])
            self.close_loop_at(self.nodes[-1])
        n = self.publish_map_path(force=True)
        rospy.loginfo('%s: %s with %d poses, the loop closed', rospy.get_name(), self.c['path'], n)

    def close_vins_loop(self):
        """loop_fusion's last keyframe closes the loop: its path at the truth up to it, and the
        VIO's drift there known from then on."""
        with self.lock:
            if not self.keyframes_added:
                return
            self.close_loop_at(self.vins_stamp((self.keyframes_added - 1) * systems.VINS_KEYFRAME_EVERY))
            n = self.keyframes_added
        rospy.loginfo('%s: %s with %d poses, the loop closed', rospy.get_name(), self.c['path'], n)
        self.publish_pose_graph_path()

if __name__ == '__main__':
    rospy.init_node('slam_stand_in')  # the launch file gives the real system's name
    StandIn()
    rospy.spin()
