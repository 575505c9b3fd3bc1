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
The boom's vertical plane (the paper's Feature II) for CEPP.

All sections of a pump boom lie in the vertical plane through the base pivot along the slew
direction ``u = (cos theta, sin theta, 0)``. In-plane coordinates of a point x are
``a = (x - b) . u`` (horizontal reach) and its height z.
"""
from epp_ros.core.solvers.compiled import kernel
import numpy as np

__all__ = ['fit_slew', 'fit_plane_to_ranges', 'slew_step', 'to_plane', 'from_plane',
           'project_ranges']

#: The compiled twin of :func:`fit_plane_to_ranges`.
KERNEL = 'epp_ros.core.model.compiled_plane'


def fit_slew(points, base):
    """
    Slew angle of the vertical plane through ``base`` that best fits ``points``.

    Total least squares on the horizontal projections (the principal direction of their
    scatter about the base), which, unlike the paper's fitted slope ``K``, is defined for
    every direction including the y-axis. The sign is chosen so that the points lie on the
    positive side on average.

    Parameters
    ----------
    points : ndarray, shape (k, 3)
        Points to fit, metres.
    base : ndarray, shape (3,)
        The boom base the plane passes through, metres.

    Returns
    -------
    slew : float, radians in [-pi, pi)

    """
    horizontal = np.asarray(points, dtype=float)[:, :2] - np.asarray(base, dtype=float)[:2]
    _, _, vt = np.linalg.svd(horizontal, full_matrices=False)
    direction = vt[0]
    if np.sum(horizontal @ direction) < 0:
        direction = -direction
    slew = float(np.arctan2(direction[1], direction[0]))
    return slew if slew < np.pi else -np.pi


def to_plane(points, base, slew):
    """In-plane coordinates (reach, z) of ``points`` (k, 3) -> (k, 2)."""
    points = np.asarray(points, dtype=float)
    offset = points[:, :2] - np.asarray(base, dtype=float)[:2]
    reach = offset @ np.array([np.cos(slew), np.sin(slew)])
    return np.column_stack([reach, points[:, 2]])


def from_plane(coords, base, slew):
    """World positions (k, 3) of in-plane coordinates (k, 2) in the plane of ``slew``."""
    coords = np.asarray(coords, dtype=float)
    base = np.asarray(base, dtype=float)
    return np.column_stack([base[0] + coords[:, 0] * np.cos(slew),
                            base[1] + coords[:, 0] * np.sin(slew), coords[:, 1]])


def project_ranges(ranges, anchors, base, slew):
    """
    Exact squared ranges, within the plane, from in-plane tags to projected anchors.

    A tag in the plane and an anchor at perpendicular distance ``d`` from it satisfy
    ``delta_plane^2 = delta^2 - d^2``. (The paper's formula uses the tag's own previous
    coordinates instead, which is not this.) Noise can make ``delta < d``; such values are
    clipped to zero and flagged.

    Parameters
    ----------
    ranges : ndarray, shape (p, m)
        Measured tag-anchor distances, NaN where missing.
    anchors : ndarray, shape (m, 3)
        Anchor positions, metres.
    base : ndarray, shape (3,)
        The boom base the plane passes through, metres.
    slew : float
        The plane's slew, radians.

    Returns
    -------
    squared : ndarray, shape (p, m)
        In-plane squared ranges (NaN where missing).
    clipped : ndarray of bool, shape (p, m)
        Where noise made the projection negative.

    """
    normal = np.array([-np.sin(slew), np.cos(slew)])
    offset = (np.asarray(anchors, dtype=float)[:, :2] - np.asarray(base, dtype=float)[:2]) @ normal
    squared = np.asarray(ranges, dtype=float) ** 2 - offset ** 2
    with np.errstate(invalid='ignore'):
        clipped = squared < 0
    return np.where(clipped, 0.0, squared), clipped


def slew_step(coords, ranges, anchors, base, slew):
    """
    Gauss-Newton step on the slew for fixed in-plane coordinates, radians.

    Minimises ``sum (||w_k(theta) - a_j|| - delta_kj)^2`` over the valid ranges, where
    ``w_k(theta) = from_plane(coords[k], base, theta)``.

    Parameters
    ----------
    coords : ndarray, shape (p, 2)
        In-plane tag positions (reach, z), metres.
    ranges : ndarray, shape (p, m)
        Metres, NaN where missing.
    anchors : ndarray, shape (m, 3)
        Anchor positions, metres.
    base : ndarray, shape (3,)
        The boom base the plane passes through, metres.
    slew : float
        Current slew, radians.

    """
    joints = from_plane(coords, base, slew)
    difference = joints[:, None, :] - np.asarray(anchors, dtype=float)[None, :, :]
    distance = np.linalg.norm(difference, axis=-1)
    valid = np.isfinite(ranges) & (distance > 1e-9)
    tangent = coords[:, 0, None] * np.array([-np.sin(slew), np.cos(slew), 0.0])  # dw/dtheta
    jac = np.einsum('kjc,kc->kj', difference, tangent) / np.where(valid, distance, 1.0)
    residual = np.where(valid, distance - np.nan_to_num(ranges), 0.0)
    jac = np.where(valid, jac, 0.0)
    curvature = np.sum(jac ** 2)
    return float(-np.sum(jac * residual) / curvature) if curvature > 1e-12 else 0.0


def fit_plane_to_ranges(coords, ranges, anchors, base, slew, pivot=None, arm_lengths=None,
                        max_iter=5, tol=1e-9):
    """
    Slew and in-plane tag positions that best fit 3-D ranges, by Gauss-Newton.

    Least squares ``sum (||w_k - a_j|| - delta_kj)^2`` over the valid ranges, where
    ``w_k = from_plane(coords[k], base, slew)``, plus, given ``arm_lengths``, the squared
    misfits of the section lengths (pivot to tag 1, tag k-1 to tag k). The slew and every
    tag's (reach, z) are free. A small ridge holds directions the data leave open.
    Compiled where the kernels are (``compiled_plane``); this numpy code is the reference.

    Parameters
    ----------
    coords : ndarray, shape (p, 2)
        Starting in-plane positions (reach, z), metres, e.g. the previous pose's.
    ranges : ndarray, shape (p, m)
        Measured tag-anchor distances, metres, NaN where missing.
    anchors : ndarray, shape (m, 3)
        Anchor positions, metres.
    base : ndarray, shape (3,)
        The boom base the plane passes through, metres.
    slew : float
        Starting slew, radians.
    pivot : ndarray, shape (2,), optional
        In-plane position of the boom's pivot; required with ``arm_lengths``.
    arm_lengths : ndarray, shape (p,), optional
        Section lengths, metres.
    max_iter : int
        Gauss-Newton iterations at most.
    tol : float
        Stop when the slew step is below this, radians.

    Returns
    -------
    slew : float
        Radians (not wrapped).
    coords : ndarray, shape (p, 2)

    """
    if arm_lengths is not None and pivot is None:
        raise ValueError('pivot: required with arm_lengths')
    if kernel(KERNEL) is not None:
        return kernel(KERNEL).fit_plane_to_ranges(coords, ranges, anchors, base, slew, pivot,
                                                  arm_lengths, max_iter, tol)
    coords = np.array(coords, dtype=float)
    anchors = np.asarray(anchors, dtype=float)
    base = np.asarray(base, dtype=float)
    valid = np.isfinite(ranges)
    measured = np.where(valid, ranges, 0.0)
    p = coords.shape[0]
    for _ in range(max_iter):
        direction = np.array([np.cos(slew), np.sin(slew), 0.0])
        tangent = np.array([-np.sin(slew), np.cos(slew), 0.0])
        difference = from_plane(coords, base, slew)[:, None, :] - anchors[None, :, :]
        distance = np.maximum(np.linalg.norm(difference, axis=-1), 1e-9)
        unit = difference / distance[..., None] * valid[..., None]      # (p, m, 3)
        # Rows: ranges (p, m), columns: slew, then (reach, z) of each tag.
        jacobian = np.zeros(valid.shape + (1 + 2 * p,))
        jacobian[..., 0] = (unit @ tangent) * coords[:, 0, None]
        tags = np.arange(p)
        jacobian[tags, :, 1 + 2 * tags] = unit @ direction
        jacobian[tags, :, 2 + 2 * tags] = unit[..., 2]
        jacobian = jacobian.reshape(-1, 1 + 2 * p)
        residual = ((distance - measured) * valid).reshape(-1)
        if arm_lengths is not None:
            jacobian, residual = _with_sections(jacobian, residual, coords, pivot, arm_lengths)
        normal = jacobian.T @ jacobian
        normal[np.diag_indices_from(normal)] += 1e-9 + 1e-9 * np.trace(normal)
        step = -np.linalg.solve(normal, jacobian.T @ residual)
        slew += step[0]
        coords += step[1:].reshape(p, 2)
        if abs(step[0]) <= tol:
            break
    return float(slew), coords


def _with_sections(jacobian, residual, coords, pivot, arm_lengths):
    """Append the section-length residuals and their Jacobian rows."""
    p = coords.shape[0]
    chain = np.vstack([pivot, coords])
    section = np.diff(chain, axis=0)                                    # (p, 2)
    length = np.maximum(np.linalg.norm(section, axis=1), 1e-9)
    unit = section / length[:, None]
    rows = np.zeros((p, jacobian.shape[1]))
    tags = np.arange(p)
    rows[tags, 1 + 2 * tags] = unit[:, 0]
    rows[tags, 2 + 2 * tags] = unit[:, 1]
    rows[tags[1:], 2 * tags[1:] - 1] = -unit[1:, 0]
    rows[tags[1:], 2 * tags[1:]] = -unit[1:, 1]
    return np.vstack([jacobian, rows]), np.concatenate([residual, length - arm_lengths])
