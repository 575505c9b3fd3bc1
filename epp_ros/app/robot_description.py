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
The boom as a robot: the pump's URDF and the joint positions of a posture.

The URDF's tree, from the pump's ``frame_id`` (the truck, REP 103: x forward, z up):

- ``slew`` (revolute about z, through ``base``) to ``turret``: x along the slew direction;
- ``boom1_joint`` (revolute, at ``pivot_offset`` along the turret's x) to ``boom1``, then
  ``boom<k>_joint`` at the end of section k - 1 to ``boom<k>``: x along section k, y the
  pitch axis; a positive angle raises the section;
- fixed frames: ``tip`` and ``tag_<name>`` at the ends of the sections (tag k rides joint
  k), ``anchor_<name>`` on the truck.

Joint positions (:func:`joint_positions`) are the slew, the first section's elevation and
each later section's angle to the one below: what ``joint_states`` carries and
robot_state_publisher turns into ``/tf``. No ROS imports: the node publishes the text, and
``epp_urdf`` writes it.
"""
import math
from xml.dom import minidom
import xml.etree.ElementTree as ElementTree

import numpy as np

__all__ = ['SLEW_JOINT', 'section_joint', 'joint_names', 'joint_positions', 'urdf']

#: Name of the slew joint.
SLEW_JOINT = 'slew'
#: Radius of the boom sections as drawn, metres.
SECTION_RADIUS = 0.15
#: Effort limit written for every joint: URDF requires one, the description has none.
NO_EFFORT_LIMIT = 0.0


def section_joint(k):
    """Return the name of the joint at the foot of section ``k`` (1-based)."""
    return f'boom{k}_joint'


def joint_names(n_sections):
    """Return the URDF's movable joints in ``joint_states`` order: the slew, then the sections."""
    return [SLEW_JOINT, *(section_joint(k) for k in range(1, n_sections + 1))]


def joint_positions(slew, pitches):
    """
    Joint positions of a posture, radians, as :func:`joint_names`.

    Parameters
    ----------
    slew : float
        Turntable angle about z from the truck's x-axis, radians.
    pitches : array_like, shape (p,)
        Elevation of each section above the horizontal, radians.

    Returns
    -------
    ndarray, shape (p + 1,)
        The slew, the first elevation, then each section's angle to the one below, wrapped
        to [-pi, pi).

    """
    pitches = np.asarray(pitches, dtype=float)
    relative = np.r_[pitches[:1], np.diff(pitches)]
    return (np.r_[slew, relative] + np.pi) % (2 * np.pi) - np.pi


def _xyz(values):
    return ' '.join(repr(float(v)) for v in values)


def _link(robot, name, visual=None):
    link = ElementTree.SubElement(robot, 'link', name=name)
    if visual is not None:
        origin, geometry, material = visual
        shape = ElementTree.SubElement(link, 'visual')
        ElementTree.SubElement(shape, 'origin', xyz=_xyz(origin[0]), rpy=_xyz(origin[1]))
        ElementTree.SubElement(ElementTree.SubElement(shape, 'geometry'), *geometry)
        ElementTree.SubElement(shape, 'material', name=material)
    return link


def _joint(robot, name, kind, parent, child, xyz, axis=None, limit=None):
    joint = ElementTree.SubElement(robot, 'joint', name=name, type=kind)
    ElementTree.SubElement(joint, 'parent', link=parent)
    ElementTree.SubElement(joint, 'child', link=child)
    ElementTree.SubElement(joint, 'origin', xyz=_xyz(xyz), rpy='0.0 0.0 0.0')
    if axis is not None:
        ElementTree.SubElement(joint, 'axis', xyz=_xyz(axis))
    if limit is not None:
        lower, upper, velocity = limit
        ElementTree.SubElement(joint, 'limit', lower=repr(lower), upper=repr(upper),
                               effort=repr(NO_EFFORT_LIMIT), velocity=repr(velocity))
    return joint


def _materials(robot):
    for name, rgba in (('boom', '1.0 0.6 0.0 1.0'), ('device', '0.2 0.2 0.2 1.0')):
        material = ElementTree.SubElement(robot, 'material', name=name)
        ElementTree.SubElement(material, 'color', rgba=rgba)


def urdf(config, max_angular_rate, name='epp_pump'):
    """
    Return the URDF of a pump, as text.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        The pump: its frame, base, pivot offset, section lengths, tags and anchors.
    max_angular_rate : float
        Fastest slew or pitch rate of the boom, rad/s: every joint's velocity limit.
    name : str
        The robot's name.

    Returns
    -------
    str
        The URDF (XML). The description gives no angle limits: every joint turns through
        [-pi, pi], as :func:`joint_positions` wraps them.

    """
    robot = ElementTree.Element('robot', name=name)
    _materials(robot)
    _link(robot, config.frame_id)
    _link(robot, 'turret', (((0.0, 0.0, -0.25), (0.0, 0.0, 0.0)),
                            ('cylinder', {'radius': '0.6', 'length': '0.5'}), 'device'))
    _joint(robot, SLEW_JOINT, 'revolute', config.frame_id, 'turret', config.base,
           axis=(0.0, 0.0, 1.0), limit=(-math.pi, math.pi, max_angular_rate))
    parent, start = 'turret', (config.pivot_offset, 0.0, 0.0)
    for k, length in enumerate(config.arm_lengths, start=1):
        section = f'boom{k}'
        _link(robot, section, (((length / 2, 0.0, 0.0), (0.0, math.pi / 2, 0.0)),
                               ('cylinder', {'radius': repr(SECTION_RADIUS),
                                             'length': repr(float(length))}), 'boom'))
        # About -y: a positive angle turns x (along the section) towards z (up).
        _joint(robot, section_joint(k), 'revolute', parent, section, start,
               axis=(0.0, -1.0, 0.0), limit=(-math.pi, math.pi, max_angular_rate))
        tag = f'tag_{config.tag_names[k - 1]}'
        _link(robot, tag)
        _joint(robot, f'{tag}_joint', 'fixed', section, tag, (length, 0.0, 0.0))
        parent, start = section, (length, 0.0, 0.0)
    _link(robot, 'tip')
    _joint(robot, 'tip_joint', 'fixed', parent, 'tip', start)
    for anchor, position in zip(config.anchor_names, config.anchor_positions):
        frame = f'anchor_{anchor}'
        _link(robot, frame, (((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                             ('sphere', {'radius': '0.2'}), 'device'))
        _joint(robot, f'{frame}_joint', 'fixed', config.frame_id, frame, position)
    text = ElementTree.tostring(robot, encoding='unicode')
    return minidom.parseString(text).toprettyxml(indent='  ')
