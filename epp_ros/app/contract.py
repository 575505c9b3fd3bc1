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

"""
The message contract of epp_ros: its topics, their QoS, and the layout of its messages.

One home for what the nodes, the bag tools, the demo and the benchmarks must agree on. No
ROS imports: the nodes build rclpy profiles and messages from it (``nodes/messages.py``), the
bag tools rosbags ones (``bags.py``), and decoding works on either kind of message.

- ``uwb/ranges`` (``sensor_msgs/JointState``): ``name[i] = "<tag>:<anchor>"`` (then any
  ``"<tag>:<tag>"``), ``position[i]`` the range in metres, NaN where not reported this cycle;
  stamped with the receive time of the newest range. ``effort[i]`` is the age of range i:
  how long before the stamp it was measured, seconds, >= 0, NaN where the range is missing
  (:func:`range_ages`, :func:`ages_of`). Tags range in their own TDMA slots, so one message
  mixes instants, and a moving boom needs each range's time; only common_interfaces
  messages are used and JointState has no per-entry stamp, hence ``effort``. An empty
  ``effort`` (older bags, other publishers) means every range was measured at the stamp;
  ``velocity`` stays empty. The last entry, ``"frame"`` (:data:`FRAME_NUMBER`), numbers
  the driver's frames 1, 2, 3, ... in ``position`` (age 0): a receiver counts a gap as
  frames lost on the way (:class:`FrameNumbers`); messages without it are not numbered.
- ``uwb/anchor_ranges`` (``sensor_msgs/JointState``): anchor-anchor ranges, as the anchors
  measure them to survey themselves (TREK1000 ``ma`` lines, DWM1001 anchors ranging each
  other): ``name[i] = "<anchor>:<anchor>"``, the measuring anchor first (the pump's anchor
  names, :func:`anchor_range_names`), ``position[i]`` the range in metres; only ranges
  reported are listed, each message one round (one device line, or one simulated round);
  stamped with the receive time; ``velocity`` and ``effort`` stay empty. Read with
  :func:`anchor_range_matrix`.
- ``arm_posture`` and ``arm_posture/ground_truth`` (``geometry_msgs/PoseArray``): the base
  pivot, then joints 1..p, each pose's x-axis along its section (:func:`posture_poses`).
- ``joint_states`` (``sensor_msgs/JointState``): the joint positions of each posture on
  ``arm_posture``, same stamp, for robot_state_publisher and ``/tf``; ``robot_description``
  (``std_msgs/String``, transient local): the pump's URDF (``epp_ros.app.robot_description``).
- ``arm_posture/markers`` (``visualization_msgs/MarkerArray``), ``boom_angles``
  (``sensor_msgs/JointState``, radians), ``/diagnostics``, ``uwb/raw`` (``std_msgs/String``).

Names are relative, so a namespace (``-r __ns:=/pump7``) moves a whole pump; bags store the
absolute names of the root namespace (:attr:`Topic.absolute`).
"""
from dataclasses import dataclass, replace
from functools import lru_cache
import math
from typing import NamedTuple

from epp_ros.core.model import boom_quaternions
import numpy as np

__all__ = ['Topic', 'RANGES', 'RANGES_INPUT', 'RANGES_SENSOR_DATA', 'ANGLES', 'POSTURE',
           'MARKERS', 'TRUTH', 'DIAGNOSTICS', 'RAW', 'JOINT_STATES', 'ROBOT_DESCRIPTION',
           'posture_poses', 'points_of', 'joints_of', 'stamp_parts', 'stamp_seconds',
           'range_ages', 'ages_of', 'LINK_SEPARATOR', 'link_name', 'link_names', 'link_ends',
           'LinkFrame', 'link_frame', 'ANCHOR_RANGES', 'anchor_range_names', 'frame_fields',
           'anchor_round_fields', 'anchor_range_matrix', 'FRAME_NUMBER', 'frame_number',
           'FrameNumbers']


@dataclass(frozen=True)
class Topic:
    """
    A topic and the QoS it is used with.

    Reliable, keep last ``depth`` (None: keep all); ``latched``: transient local, so a
    subscriber that comes later still gets the last message (a robot description).
    """

    name: str
    type: str  # noqa: A003 (public field mirroring a ROS topic's type; shadows nothing in scope)
    depth: int = 10
    reliable: bool = True
    latched: bool = False

    @property
    def absolute(self):
        """Return the name in the root namespace, as bags store it."""
        return self.name if self.name.startswith('/') else '/' + self.name


#: Reliable and deep: serves reliable and best-effort subscribers. The writer keeps the
#: newest 100 frames for a reader that has not acknowledged them, so a driver never waits
#: for a stalled reader: a reader more than 100 frames behind loses the older ones, and
#: counts them from the frames' numbers (:class:`FrameNumbers`).
RANGES = Topic('uwb/ranges', 'sensor_msgs/msg/JointState', depth=100)
#: The estimator's subscription: keep all, so its own queue never overwrites a frame it has
#: not taken (a slow node shows as latency; what the writer could not keep is counted lost).
RANGES_INPUT = replace(RANGES, depth=None)
#: The estimator's subscription with ``ranges_qos: sensor_data``: REP 2003's sensor-data
#: profile (best effort, keep last 5), for publishers that offer nothing else; frames DDS
#: drops are counted lost, from the numbers, as above.
RANGES_SENSOR_DATA = replace(RANGES, depth=5, reliable=False)
#: Reliable and deep, as ``uwb/ranges``: a start-up burst of rounds loses nothing.
ANCHOR_RANGES = Topic('uwb/anchor_ranges', 'sensor_msgs/msg/JointState', depth=100)
ANGLES = Topic('boom_angles', 'sensor_msgs/msg/JointState', depth=None)
POSTURE = Topic('arm_posture', 'geometry_msgs/msg/PoseArray')
MARKERS = Topic('arm_posture/markers', 'visualization_msgs/msg/MarkerArray')
#: Reliable and deep, as ``uwb/ranges``: whoever checks the ranges against it loses no cycle
#: while it is busy.
TRUTH = Topic('arm_posture/ground_truth', 'geometry_msgs/msg/PoseArray', depth=100)
DIAGNOSTICS = Topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')
#: The published postures' joint positions (``robot_description.joint_names``), radians.
JOINT_STATES = Topic('joint_states', 'sensor_msgs/msg/JointState')
#: The pump's URDF (``robot_description.urdf``), as robot_state_publisher offers it.
ROBOT_DESCRIPTION = Topic('robot_description', 'std_msgs/msg/String', depth=1, latched=True)
RAW = Topic('uwb/raw', 'std_msgs/msg/String', depth=100)


#: The ``uwb/ranges`` entry that numbers the driver's frames (link names have a colon).
FRAME_NUMBER = 'frame'


def frame_number(names, positions):
    """
    Return a ``uwb/ranges`` message's frame number, None when it carries none.

    Parameters
    ----------
    names, positions : sequence
        The message's ``name`` and ``position``.

    """
    names = list(names)
    if not names or names[-1] != FRAME_NUMBER or len(positions) != len(names):
        return None
    number = float(positions[-1])
    return int(number) if math.isfinite(number) and number >= 1 and number.is_integer() \
        else None


class FrameNumbers:
    """
    Counts the frames a receiver never got, from the numbers of those it got.

    Attributes
    ----------
    lost : int
        Frames numbered between two received ones: lost on the way (a receiver that fell
        behind a writer's history, a network that dropped them).
    before_first : int
        Frames the sender numbered before the first one received (published before this
        receiver was listening), and before the first of each restart of the sender.
    restarts : int
        Times the numbers started again (a restarted driver).

    """

    def __init__(self):
        self.last = None
        self.lost = self.before_first = self.restarts = 0

    def add(self, number):
        """Take the number of a received frame (None: not numbered, nothing counted)."""
        if number is None:
            return
        if self.last is None or number <= self.last:
            self.restarts += self.last is not None
            self.before_first += number - 1
        else:
            self.lost += number - self.last - 1
        self.last = number


def posture_poses(base, joints):
    """
    Return the poses of a PoseArray posture: (position (3,), quaternion (x, y, z, w)) each.

    Parameters
    ----------
    base : ndarray, shape (3,)
        The boom's pivot, metres.
    joints : ndarray, shape (p, 3)
        Joints 1..p, metres.

    Returns
    -------
    list of (tuple, tuple)
        p + 1 poses of floats: the pivot first; pose k's x-axis along section k, its z-axis
        up in the boom's vertical plane.

    """
    return [(tuple(float(v) for v in position), tuple(float(v) for v in quaternion))
            for position, quaternion in zip([base, *joints], boom_quaternions(base, joints))]


def points_of(message):
    """Return the pivot then joints 1..p, (p + 1, 3), of a PoseArray posture (rclpy or rosbags)."""
    return np.array([[pose.position.x, pose.position.y, pose.position.z]
                     for pose in message.poses], dtype=float).reshape(-1, 3)


def joints_of(message):
    """Joints 1..p (p, 3) of a PoseArray posture (rclpy or rosbags), without the pivot."""
    return points_of(message)[1:]


def stamp_parts(seconds):
    """``(sec, nanosec)`` of a time in seconds, nanoseconds rounded and kept below 1e9."""
    sec = math.floor(seconds)
    return int(sec), min(int(round((seconds - sec) * 1e9)), 999_999_999)


def stamp_seconds(stamp):
    """Seconds of a ``builtin_interfaces/Time`` (rclpy or rosbags)."""
    return stamp.sec + 1e-9 * stamp.nanosec


def range_ages(stamp, measured):
    """
    Return the ``effort`` of a ``uwb/ranges`` message: the age of each of its ranges.

    Parameters
    ----------
    stamp : float
        The message's stamp, seconds.
    measured : array_like, shape (n,)
        When each range was measured, seconds on the clock of ``stamp``; NaN for a
        missing range.

    Returns
    -------
    ndarray, shape (n,)
        ``stamp - measured`` in seconds, at least 0, NaN where ``measured`` is NaN.

    """
    measured = np.asarray(measured, dtype=float)
    with np.errstate(invalid='ignore'):
        return np.where(np.isfinite(measured), np.maximum(stamp - measured, 0.0), np.nan)


def ages_of(effort, count):
    """
    Return the ages of a ``uwb/ranges`` message's ranges, or None when it carries none.

    Parameters
    ----------
    effort : sequence of float
        The message's ``effort``, seconds (:func:`range_ages`).
    count : int
        The message's ranges (``len(name)``).

    Returns
    -------
    ndarray, shape (count,), or None
        Seconds before the stamp each range was measured; NaN where unknown (a negative or
        non-finite age). None for an empty ``effort``: every range at the stamp.

    Raises
    ------
    ValueError
        When ``effort`` is neither empty nor one age per range.

    """
    if len(effort) == 0:
        return None
    if len(effort) != count:
        raise ValueError(f'{len(effort)} ages (effort) for {count} ranges: '
                         'need one per range or none')
    ages = np.asarray(effort, dtype=float)
    with np.errstate(invalid='ignore'):
        return np.where(np.isfinite(ages) & (ages >= 0), ages, np.nan)


#: Between the two device names of a link: ``"<tag>:<anchor>"``, ``"<tag>:<tag>"``,
#: ``"<anchor>:<anchor>"`` (device names hold letters, digits and _ only).
LINK_SEPARATOR = ':'


def link_name(first, second):
    """Return the name of the link ``first`` measured to ``second``: ``"<first>:<second>"``."""
    return f'{first}{LINK_SEPARATOR}{second}'


def link_names(tag_names, anchor_names):
    """Return every ``"<tag>:<anchor>"`` name, tag-major: row k, column j at k m + j."""
    return [link_name(tag, anchor) for tag in tag_names for anchor in anchor_names]


def link_ends(name):
    """Return the two device names of a link's name, the measuring one first."""
    first, _, second = str(name).partition(LINK_SEPARATOR)
    return first, second


class LinkFrame(NamedTuple):
    """One ``uwb/ranges`` message arranged for the estimators (:func:`link_frame`)."""

    #: (p, m) tag-anchor ranges, metres, NaN where a pair is absent
    ranges: np.ndarray
    #: (p, p) tag-tag ranges, metres, row the measuring tag, NaN where absent
    tag_ranges: np.ndarray
    #: (p,) seconds before the stamp each tag's row was measured (the median of its ranges'
    #: ages), NaN where unknown; None when the message carries no ages
    ages: np.ndarray | None
    #: labels that name no configured pair (ignored)
    unknown: int

    def range_stamps(self, stamp):
        """
        Return when each tag's row was measured, as ``PostureEstimator.update`` takes it.

        Parameters
        ----------
        stamp : float
            The message's stamp, seconds.

        Returns
        -------
        ndarray, shape (p,), or None
            ``stamp - ages`` in seconds, NaN (at the stamp) where unknown; None without ages.

        """
        return None if self.ages is None else stamp - self.ages


def _tag_ages(ranges, ages):
    """
    Reduce the ages of each tag's ranges to one: the median of those known.

    Parameters
    ----------
    ranges : ndarray, shape (p, m)
        Tag-anchor ranges, metres, NaN where absent (their ages do not count).
    ages : ndarray, shape (p, m)
        Their ages, seconds, NaN where unknown.

    Returns
    -------
    ndarray, shape (p,)
        Seconds, NaN for a tag without a range of known age.

    """
    known = np.isfinite(ranges) & np.isfinite(ages)
    return np.array([np.median(row[mask]) if mask.any() else np.nan
                     for row, mask in zip(ages, known)])


@lru_cache(maxsize=8)
def _link_index(tag_names, anchor_names):
    """Return each link name's flat position in the (p, m) and the (p, p) arrays."""
    p = len(tag_names)
    links = {name: i for i, name in enumerate(link_names(tag_names, anchor_names))}
    tag_links = {link_name(tag_names[row], tag_names[column]): row * p + column
                 for row in range(p) for column in range(p) if row != column}
    return links, tag_links


def link_frame(names, values, tag_names, anchor_names, ages=None):
    """
    Arrange a ``uwb/ranges`` message's ranges, and their ages, for the estimators.

    Parameters
    ----------
    names : sequence of str
        ``"<tag>:<anchor>"`` and ``"<tag>:<tag>"`` labels, in any order (a
        :data:`FRAME_NUMBER` entry is not a link).
    values : sequence of float
        The ranges, metres (NaN for missing).
    tag_names, anchor_names : tuple of str
        The pump's devices, by index.
    ages : sequence of float, optional
        The message's ``effort``: seconds before its stamp each range was measured
        (:func:`ages_of`); empty or None: every range at the stamp.

    Returns
    -------
    LinkFrame
        The (p, m) and (p, p) ranges, each tag's age (p,) and the unknown labels.

    Raises
    ------
    ValueError
        When ``values``, or a non-empty ``ages``, is not one per name.

    """
    if len(names) != len(values):
        raise ValueError(f'{len(names)} names but {len(values)} ranges')
    link_ages = None if ages is None else ages_of(ages, len(names))
    links, tag_links = _link_index(tuple(tag_names), tuple(anchor_names))
    p, m = len(tag_names), len(anchor_names)
    ranges, tag_ranges = np.full((p, m), np.nan), np.full((p, p), np.nan)
    ages_by_link = np.full((p, m), np.nan)
    unknown = 0
    for i, (name, value) in enumerate(zip(names, values)):
        if name == FRAME_NUMBER:
            continue
        position = links.get(name)
        if position is not None:
            ranges.flat[position] = value
            if link_ages is not None:
                ages_by_link.flat[position] = link_ages[i]
            continue
        position = tag_links.get(name)
        if position is None:
            unknown += 1
        else:
            tag_ranges.flat[position] = value
    tag_ages = None if link_ages is None else _tag_ages(ranges, ages_by_link)
    return LinkFrame(ranges, tag_ranges, tag_ages, unknown)


def anchor_range_names(anchor_names, rows, columns):
    """
    Return the labels of ``uwb/anchor_ranges`` entries: ``"<anchor>:<anchor>"``.

    Parameters
    ----------
    anchor_names : sequence of str
        The pump's anchor names, by index.
    rows, columns : sequence of int
        Each entry's measuring anchor and the anchor it ranged to (indices).

    Returns
    -------
    list of str
        The measuring anchor's name first.

    """
    return [link_name(anchor_names[i], anchor_names[j]) for i, j in zip(rows, columns)]


def frame_fields(frame, config):
    """
    Return a frame as ``uwb/ranges`` carries it.

    A numbered frame carries its number last, as :data:`FRAME_NUMBER`.

    Parameters
    ----------
    frame : epp_ros.uwb.frames.Frame
        One ranging cycle.
    config : epp_ros.app.config.PumpConfig
        The pump: the names of the links.

    Returns
    -------
    names : list of str
        Every ``"<tag>:<anchor>"`` pair, tag-major, then ``"<tag>:<tag>"`` for each
        tag-tag range reported, then the number.
    ranges : list of float
        Metres, NaN where a pair did not report; then the number.
    ages : list of float
        Seconds before the frame's stamp each range was received, NaN where it is
        missing; then 0.

    """
    rows, columns = np.nonzero(np.isfinite(frame.tag_ranges))
    names = config.link_names + [config.tag_link_name(row, column)
                                 for row, column in zip(rows, columns)]
    ranges = np.concatenate([frame.ranges.ravel(), frame.tag_ranges[rows, columns]])
    received = np.concatenate([frame.received.ravel(), frame.tag_received[rows, columns]])
    ages = range_ages(frame.stamp, received).tolist()
    if frame.number is None:
        return names, ranges.tolist(), ages
    return ([*names, FRAME_NUMBER], [*ranges.tolist(), float(frame.number)], [*ages, 0.0])


def anchor_round_fields(anchor_round, config):
    """
    Return an anchor round as ``uwb/anchor_ranges`` carries it.

    Parameters
    ----------
    anchor_round : epp_ros.uwb.frames.AnchorRound
        Anchor-anchor ranges received together.
    config : epp_ros.app.config.PumpConfig
        The pump: the anchors' names.

    Returns
    -------
    names : list of str
        ``"<anchor>:<anchor>"``, the measuring anchor first.
    ranges : list of float
        Metres.

    """
    return (anchor_range_names(config.anchor_names, anchor_round.rows, anchor_round.columns),
            [float(value) for value in anchor_round.ranges])


def anchor_range_matrix(anchor_names, names, values):
    """
    Arrange a ``uwb/anchor_ranges`` message into a matrix of anchor-anchor ranges.

    Parameters
    ----------
    anchor_names : sequence of str
        The pump's anchor names (m).
    names : sequence of str
        The message's ``name``: ``"<anchor>:<anchor>"``, measuring anchor first.
    values : sequence of float
        The message's ``position``, metres.

    Returns
    -------
    ranges : ndarray, shape (m, m)
        Row i: anchor i's ranges, metres; NaN where not reported (always on the diagonal).
    unknown : int
        Labels that name no pair of two different configured anchors (ignored).

    Raises
    ------
    ValueError
        When ``names`` and ``values`` differ in length.

    """
    if len(names) != len(values):
        raise ValueError(f'{len(names)} names but {len(values)} ranges')
    index = {name: j for j, name in enumerate(anchor_names)}
    ranges = np.full((len(anchor_names), len(anchor_names)), np.nan)
    unknown = 0
    for name, value in zip(names, values):
        first, second = link_ends(name)
        i, j = index.get(first), index.get(second)
        if i is None or j is None or i == j:
            unknown += 1
        else:
            ranges[i, j] = value
    return ranges, unknown
