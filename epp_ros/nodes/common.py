"""What every epp_ros node shares: parameters, the pump description, messages, main()."""
import math
import sys

import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseArray
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import Marker, MarkerArray

from epp_ros.config import PUMP_PARAMETERS, ConfigError, pump_config_from_parameters
from epp_ros.core.poses import boom_quaternions

#: /uwb/ranges: reliable, deep: serves reliable and best-effort subscribers, and a fast bag
#: replay loses nothing.
RANGES_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                        history=HistoryPolicy.KEEP_LAST, depth=100)
#: The estimator's subscription to uwb/ranges: reliable, keep all. DDS then never overwrites
#: a frame the node has not taken (a keep-last queue would drop silently when it lags):
#: a slow node shows as latency, and a fast replay is flow-controlled instead of lossy.
RANGES_INPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                              history=HistoryPolicy.KEEP_ALL)
#: Postures (estimate and ground truth): reliable, keep last 10.
POSTURE_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST, depth=10)


class StartupError(Exception):
    """A node cannot start; the message is one line for the user."""


def declare(node, name, default, description, **descriptor):
    """Declare a parameter with a descriptor and return its value.

    Raises
    ------
    StartupError
        When the value given does not fit the parameter (e.g. an integer for a float).
    """
    try:
        node.declare_parameter(name, default,
                               ParameterDescriptor(description=description, **descriptor))
    except ParameterException as exc:
        raise StartupError(f'{name}: {exc}') from None
    return node.get_parameter(name).value


def declare_pump_parameters(node):
    """Declare the shared pump description and return it validated.

    Raises
    ------
    StartupError
        Naming the offending field.
    """
    values = {name: declare(node, name, default, description, dynamic_typing=True)
              for name, (default, description) in PUMP_PARAMETERS.items()}
    try:
        return pump_config_from_parameters(values)
    except ConfigError as exc:
        raise StartupError(f'bad pump configuration: {exc}') from None


def to_time(seconds):
    """builtin_interfaces/Time from seconds since the epoch."""
    sec = math.floor(seconds)
    return Time(sec=int(sec), nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


def to_seconds(stamp):
    """Seconds since the epoch from a builtin_interfaces/Time."""
    return stamp.sec + 1e-9 * stamp.nanosec


def _stamp(stamp):
    return stamp if isinstance(stamp, Time) else to_time(stamp)


def posture_message(base, joints, stamp, frame_id):
    """PoseArray of the base pivot then joints 1..p, oriented along the sections.

    ``stamp`` is a builtin_interfaces/Time (copied exactly) or seconds.
    """
    message = PoseArray()
    message.header.stamp = _stamp(stamp)
    message.header.frame_id = frame_id
    quaternions = boom_quaternions(base, joints)
    for position, quaternion in zip([base, *joints], quaternions):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in position)
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = (float(v) for v in quaternion)
        message.poses.append(pose)
    return message


def posture_markers(base, joints, stamp, frame_id, namespace='boom'):
    """MarkerArray for RViz: the boom as a line strip, joint spheres and a tip label."""
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
    for marker in (strip, spheres, label):
        marker.header.stamp = header_stamp
        marker.header.frame_id = frame_id
        marker.pose.orientation.w = 1.0
    return MarkerArray(markers=[strip, spheres, label])


def run_node(factory, args=None):
    """The usual node main(): init, construct, spin, shut down; exit status 2 on StartupError."""
    rclpy.init(args=sys.argv if args is None else args)
    node = None
    status = 0
    try:
        node = factory()
        rclpy.spin(node)
    except StartupError as exc:
        name = node.get_name() if node is not None else factory.__name__
        print(f'{getattr(factory, "node_name", name)}: {exc}', file=sys.stderr)
        status = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status
