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
Orientations of the boom's sections, for publishing a posture as poses.

Pose 0 is the base pivot, pose k (k = 1..p) joint k. Pose k's x-axis points along section k
(from joint k-1 to joint k) and its z-axis lies in the section's vertical plane, pointing up;
the base pose points along the slew, level. Quaternions are (x, y, z, w).
"""
from epp_ros.core.model.plane import fit_slew
import numpy as np

__all__ = ['boom_frames', 'rotation_to_quaternion', 'boom_quaternions']


def boom_frames(base, joints):
    """
    Rotation matrices of the base and each section.

    Parameters
    ----------
    base : ndarray, shape (3,)
        Base pivot of the boom, metres.
    joints : ndarray, shape (p, 3)
        Joint positions 1..p, metres.

    Returns
    -------
    rotations : ndarray, shape (p + 1, 3, 3)
        Columns are the frame's x, y, z axes in the world frame. Section k: x along the
        section, y horizontal (``z_world x x``), z = x cross y, which has a non-negative
        vertical component. The base, and any vertical section, use the slew fitted to the
        joints (``plane.fit_slew``) for their horizontal axes.

    """
    base = np.asarray(base, dtype=float)
    joints = np.asarray(joints, dtype=float)
    reach = np.linalg.norm(joints[:, :2] - base[:2], axis=1)
    slew = fit_slew(joints, base) if reach.max() > 1e-9 else 0.0   # straight up: +x
    rotations = np.zeros((len(joints) + 1, 3, 3))
    # The base: x along the slew, y = z_world x x, z up.
    rotations[0, :2, 0] = np.cos(slew), np.sin(slew)
    rotations[0, :2, 1] = -rotations[0, 1, 0], rotations[0, 0, 0]
    rotations[0, 2, 2] = 1.0
    sections = np.diff(np.vstack([base, joints]), axis=0)
    x_axes = sections / np.linalg.norm(sections, axis=1, keepdims=True)
    # z_world x x = (-x_y, x_x, 0), its length the section's horizontal share.
    y_axes = np.zeros_like(x_axes)
    y_axes[:, 0], y_axes[:, 1] = -x_axes[:, 1], x_axes[:, 0]
    norms = np.linalg.norm(y_axes, axis=1, keepdims=True)
    y_axes = np.where(norms > 1e-9, y_axes / np.maximum(norms, 1e-12), rotations[0, :, 1])
    rotations[1:, :, 0], rotations[1:, :, 1] = x_axes, y_axes
    # x cross y, y horizontal: (-x_z y_y, x_z y_x, x_x y_y - x_y y_x).
    rotations[1:, 0, 2] = -(x_axes[:, 2] * y_axes[:, 1])
    rotations[1:, 1, 2] = x_axes[:, 2] * y_axes[:, 0]
    rotations[1:, 2, 2] = x_axes[:, 0] * y_axes[:, 1] - x_axes[:, 1] * y_axes[:, 0]
    return rotations


def rotation_to_quaternion(rotations):
    """Return unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3), w >= 0."""
    r = np.asarray(rotations, dtype=float)
    trace = np.trace(r, axis1=-2, axis2=-1)
    candidates = np.stack([
        np.stack([1 + 2 * r[..., 0, 0] - trace, r[..., 0, 1] + r[..., 1, 0],
                  r[..., 0, 2] + r[..., 2, 0], r[..., 2, 1] - r[..., 1, 2]], -1),
        np.stack([r[..., 0, 1] + r[..., 1, 0], 1 + 2 * r[..., 1, 1] - trace,
                  r[..., 1, 2] + r[..., 2, 1], r[..., 0, 2] - r[..., 2, 0]], -1),
        np.stack([r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1],
                  1 + 2 * r[..., 2, 2] - trace, r[..., 1, 0] - r[..., 0, 1]], -1),
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1], 1 + trace], -1)], axis=-2)
    # Take the numerically best of the four formulas (largest diagonal term).
    best = np.argmax(np.stack([candidates[..., i, i] for i in range(4)], -1), axis=-1)
    quaternion = np.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    quaternion /= np.linalg.norm(quaternion, axis=-1, keepdims=True)
    return np.where(quaternion[..., 3:] < 0, -quaternion, quaternion)


def boom_quaternions(base, joints):
    """
    Orientation (x, y, z, w) of the base and of each section, shape (p + 1, 4), w >= 0.

    The frames of :func:`boom_frames`, written directly: each is a yaw (the section's
    heading; the slew for the base and a vertical section) after a pitch (its elevation),
    ``q = q_z(yaw) q_y(-pitch)``: a posture is published every frame, and this is a third
    of :func:`rotation_to_quaternion`'s work.
    """
    base = np.asarray(base, dtype=float)
    joints = np.asarray(joints, dtype=float)
    sections = np.diff(np.vstack([base, joints]), axis=0)
    horizontal = np.hypot(sections[:, 0], sections[:, 1])
    slew = fit_slew(joints, base) if np.max(np.hypot(*(joints[:, :2] - base[:2]).T)) > 1e-9 \
        else 0.0
    yaw = np.concatenate([[slew], np.where(horizontal / np.linalg.norm(sections, axis=1) > 1e-9,
                                           np.arctan2(sections[:, 1], sections[:, 0]), slew)])
    pitch = np.concatenate([[0.0], np.arctan2(sections[:, 2], horizontal)])
    yaw_sin, yaw_cos = np.sin(yaw / 2), np.cos(yaw / 2)
    pitch_sin, pitch_cos = np.sin(pitch / 2), np.cos(pitch / 2)
    return np.column_stack([yaw_sin * pitch_sin, -yaw_cos * pitch_sin, yaw_sin * pitch_cos,
                            yaw_cos * pitch_cos])
