# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The nodes' side of the message contract: rclpy QoS profiles, stamps and messages."""
from builtin_interfaces.msg import Duration, Time
from epp_ros.app import contract
from geometry_msgs.msg import Point, Pose, PoseArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import Marker, MarkerArray


def qos(topic):
    """Return the rclpy QoS profile of a :class:`epp_ros.app.contract.Topic`."""
    reliability = ReliabilityPolicy.RELIABLE if topic.reliable else \
        ReliabilityPolicy.BEST_EFFORT
    durability = DurabilityPolicy.TRANSIENT_LOCAL if topic.latched else \
        DurabilityPolicy.VOLATILE
    if topic.depth is None:
        return QoSProfile(reliability=reliability, durability=durability,
                          history=HistoryPolicy.KEEP_ALL)
    return QoSProfile(reliability=reliability, durability=durability,
                      history=HistoryPolicy.KEEP_LAST, depth=topic.depth)


#: The profiles of the message contract (``epp_ros.app.contract``), by use.
RANGES_QOS = qos(contract.RANGES)
RANGES_INPUT_QOS = qos(contract.RANGES_INPUT)
#: The estimator's choice of input profile (its read-only ``ranges_qos`` parameter).
RANGES_INPUT_PROFILES = {'reliable': RANGES_INPUT_QOS,
                         'sensor_data': qos(contract.RANGES_SENSOR_DATA)}
POSTURE_QOS = qos(contract.POSTURE)
TRUTH_QOS = qos(contract.TRUTH)


def to_time(seconds):
    """builtin_interfaces/Time from seconds since the epoch."""
    sec, nanosec = contract.stamp_parts(seconds)
    return Time(sec=sec, nanosec=nanosec)


#: Seconds since the epoch from a builtin_interfaces/Time.
to_seconds = contract.stamp_seconds


def _stamp(stamp):
    return stamp if isinstance(stamp, Time) else to_time(stamp)


def posture_message(base, joints, stamp, frame_id):
    """
    Return a PoseArray of the base pivot then joints 1..p, oriented along the sections.

    ``stamp`` is a builtin_interfaces/Time (copied exactly) or seconds.
    """
    message = PoseArray()
    message.header.stamp = _stamp(stamp)
    message.header.frame_id = frame_id
    for position, quaternion in contract.posture_poses(base, joints):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = position
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = quaternion
        message.poses.append(pose)
    return message


#: Seconds RViz shows a boom's markers: ten frames at 10 Hz. While frames are refused none
#: are published, and the last boom must not stay on screen as if it were still valid.
MARKER_LIFETIME = 1.0


def posture_markers(base, joints, stamp, frame_id, namespace='boom'):
    """
    Return a MarkerArray for RViz: the boom as a line strip, joint spheres, a tip label.

    Each lives :data:`MARKER_LIFETIME` seconds unless the next frame's replaces it.
    """
    header_stamp = _stamp(stamp)
    points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in [base, *joints]]
    strip = Marker(ns=namespace, id=0, type=Marker.LINE_STRIP, action=Marker.ADD,
                   points=points)
    strip.scale.x = 0.3
    strip.color.r, strip.color.g, strip.color.b, strip.color.a = 1.0, 0.6, 0.0, 1.0
    spheres = Marker(ns=namespace, id=1, type=Marker.SPHERE_LIST, action=Marker.ADD,
                     points=points)
    spheres.scale.x = spheres.scale.y = spheres.scale.z = 0.6
    spheres.color.r, spheres.color.g, spheres.color.b, spheres.color.a = 0.2, 0.2, 0.2, 1.0
    label = Marker(ns=namespace, id=2, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD,
                   text=f'tip {joints[-1][2]:.1f} m')
    label.pose.position = Point(x=points[-1].x, y=points[-1].y, z=points[-1].z + 1.0)
    label.pose.orientation.w = 1.0
    label.scale.z = 0.8
    label.color.r = label.color.g = label.color.b = label.color.a = 1.0
    lifetime = Duration(sec=int(MARKER_LIFETIME),
                        nanosec=int(round(MARKER_LIFETIME % 1.0 * 1e9)))
    for marker in (strip, spheres, label):
        marker.header.stamp = header_stamp
        marker.header.frame_id = frame_id
        marker.pose.orientation.w = 1.0
        marker.lifetime = lifetime
    return MarkerArray(markers=[strip, spheres, label])
