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

"""What every epp_ros node shares: parameters, the pump description, messages, main()."""
import os
from pathlib import Path
import re
import sys
import tempfile

from builtin_interfaces.msg import Duration, Time
from epp_ros.app import contract
from epp_ros.app.config import ConfigError, pump_config_from_parameters, PUMP_PARAMETERS
from epp_ros.nodes.stopping import ignore_signals, shutdown_on_signals
from geometry_msgs.msg import Point, Pose, PoseArray
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from visualization_msgs.msg import Marker, MarkerArray
import yaml


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

#: rclpy's error type for a failed rcl call (not exported under a public name).
RCLError = rclpy_implementation.RCLError
#: How often the spinning node looks at the shutdown request, s.
SIGNAL_POLL = 0.1


class StartupError(Exception):
    """A node cannot start; the message is one line for the user."""


def declare(node, name, default, description, **descriptor):
    """
    Declare a parameter with a descriptor and return its value.

    Raises
    ------
    StartupError
        When the value given does not fit the parameter (e.g. an integer for a float).

    """
    empty = _empty_list_given(node, name, default)
    try:
        node.declare_parameter(name, [] if empty else default,
                               ParameterDescriptor(description=description, **descriptor),
                               ignore_override=empty)
    except ParameterException as exc:
        raise StartupError(f'{name}: {exc}') from None
    return node.get_parameter(name).value


def _empty_list_given(node, name, default):
    """
    Tell whether a list parameter was given as an empty list.

    rcl reads ``[]`` in a parameters file, which ``ros2 param dump`` writes for an empty
    list, as "no value"; for a list parameter that can only mean the empty list. rclpy
    keeps the overrides in a private attribute only.
    """
    given = node._parameter_overrides.get(name)     # noqa: SLF001 - no public accessor
    return (isinstance(default, list) and given is not None
            and given.type_ == Parameter.Type.NOT_SET)


def declare_pump_parameters(node):
    """
    Declare the shared pump description and return it validated.

    Raises
    ------
    StartupError
        Naming the offending field.

    """
    values = {name: declare(node, name, default, description + ' Read-only.',
                            dynamic_typing=True, read_only=True)
              for name, (default, description) in PUMP_PARAMETERS.items()}
    try:
        return pump_config_from_parameters(values)
    except ConfigError as exc:
        raise StartupError(f'bad pump configuration: {exc}') from None


def pump_id(node, frame_id):
    """
    Return the hardware id of this pump in ``/diagnostics``: its namespace and frame.

    ``pump7/pump_base`` under the namespace ``/pump7``, ``pump_base`` at the root: two
    pumps' statuses on one ``/diagnostics`` stay apart.
    """
    namespace = node.get_namespace().strip('/')
    return f'{namespace}/{frame_id}' if namespace else frame_id


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


#: rcl's text for the parameters file it could not read: the path, then its reason.
_PARAMS_FILE_ERROR = re.compile(r"params file: '--params-file (?P<path>[^']*)'\. "
                                r'Error: (?P<reason>.*)')
#: rcl appends where in its C sources an error was raised: of no use to the user.
_SOURCE_LOCATION = re.compile(r',? at /\S+:\d+')


def _mixed_list(document, prefix=''):
    """Name of the first list in a parsed parameters file mixing integers and floats."""
    if isinstance(document, dict):
        for key, value in document.items():
            found = _mixed_list(value, f'{key}')
            if found:
                return found
    elif isinstance(document, list):
        kinds = {type(v) for v in document if isinstance(v, (int, float))
                 and not isinstance(v, bool)}
        if kinds == {int, float}:
            return f'{prefix}: {document} mixes integers and floats (write 0.0, not 0)'
    return None


def _params_file_problem(path, reason):
    """One line naming what is wrong with a parameters file rcl could not parse."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        return f'parameters file {path}: {exc.strerror or exc}'
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1})' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        return f'parameters file {path}: not valid YAML{where}: {problem}'
    if not isinstance(document, dict):
        return (f'parameters file {path}: the top level must map node names to sections '
                f'(e.g. "/**:"), not {type(document).__name__}')
    for name, section in document.items():
        if not isinstance(section, dict) or 'ros__parameters' not in section:
            return f'parameters file {path}: section {name!r} has no ros__parameters'
    mixed = _mixed_list(document)
    if mixed:
        return f'parameters file {path}: {mixed}'
    return f'parameters file {path}: {reason}'


def _init_problem(exc):
    """One line for the RCLError of rclpy.init (its text is rcl's, with C source places)."""
    text = _SOURCE_LOCATION.sub('', str(exc)).strip()
    match = _PARAMS_FILE_ERROR.search(text)
    if match:
        return _params_file_problem(match['path'], match['reason'])
    return f'the ROS arguments: {text}'


def _init(args):
    """
    rclpy.init without rclpy's signal handlers; StartupError with one line if it fails.

    rcl logs its own ERROR line to stderr (fd 2, from C) before the exception: it is held
    back while init runs and given back unless init failed, so the user sees one line.
    """
    sys.stderr.flush()
    saved = os.dup(2)
    failed = None
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError as exc:
            failed = _init_problem(exc)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if failed is None:
            held.seek(0)
            os.write(2, held.read())
    if failed is not None:
        raise StartupError(failed)


def _spin(node, stop):
    """
    Spin until a shutdown is requested or the context is shut down elsewhere.

    The request is polled: Python runs signal handlers only between rclpy's waits.
    """
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.requested and executor.context.ok():
            executor.spin_once(timeout_sec=SIGNAL_POLL)
    finally:
        executor.remove_node(node)


def _close(node):
    """Stop the node's own threads, then destroy it; each step once, whatever happens."""
    close = getattr(node, 'close', None)
    try:
        if close is not None:
            close()
    finally:
        node.destroy_node()


def run_node(factory, args=None, name=None):
    """
    Run the usual node main(): init, construct, spin, shut down; return the exit status.

    SIGINT and SIGTERM, however many and whenever, end it cleanly with status 0 (an
    RCLError once shutdown began counts as clean); a StartupError, including a parameters
    file or ROS argument rcl cannot parse, prints one line and returns 2.
    """
    stop = shutdown_on_signals()
    name = name or getattr(factory, 'node_name', factory.__name__)
    node = None
    try:
        _init(sys.argv if args is None else args)
        if not stop.requested:
            node = factory()
            _spin(node, stop)
    except StartupError as exc:
        print(f'{name}: {exc}', file=sys.stderr)
        return 2
    except ExternalShutdownException:
        pass
    except (RCLError, InvalidHandle):
        if not stop.requested:
            raise
    finally:
        _shut_down(node, stop)
        ignore_signals()
    return 0


def _shut_down(node, stop):
    """Close the node and rclpy; once shutdown was requested, rclpy errors are expected."""
    try:
        if node is not None:
            _close(node)
    except (RCLError, InvalidHandle):
        if not stop.requested:
            raise
    finally:
        rclpy.try_shutdown()
