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
A frame's bounds compiled: ``core.model.bounds.frame_bounds`` in one function.

The numpy path is the reference: the Jacobian of the kept links (``Residuals.rows``), the
Fisher information and its inverse (one symmetric eigendecomposition, as
``bound_from_information``), each joint's covariance, the poorly controlled links'
increase (``uncontrolled_covariance``) and the common bias's (``bias_covariance``). Each is
some ten numpy calls on arrays of a few dozen elements, whose calls, not their
arithmetic, were the time (issue #30). Imported at first use only (``solvers.compiled``).
"""
from epp_ros.core.model.bounds import DETERMINED, LEAST_REDUNDANCY
from epp_ros.core.model.compiled_boom import joint_jacobian_at, joints_at, range_row
from epp_ros.core.solvers.compiled import compiled, plain
import numpy as np

__all__ = ['compile_now', 'frame_bounds', 'RANDOM_ONLY', 'UNBOUNDED', 'WIDENED']

#: What :func:`frame_bounds` found: no bound; the bound, nothing added; the bound and
#: a wider one. (A joint's variance lost to rounding is ``bounds._bound``'s to judge.)
UNBOUNDED, RANDOM_ONLY, WIDENED = 0, 1, 2


@compiled
def _joint_covariance(moved, covariance):
    """Return each joint's covariance (p, 3, 3) from psi's and the joints' derivatives."""
    out = np.empty((moved.shape[0], 3, 3))
    for k in range(moved.shape[0]):
        out[k] = moved[k] @ covariance @ moved[k].T
    return out


@compiled
def _bounds(psi, geometry, pivot_offset, layout, sigma, design, common, floor):
    """Compiled :func:`frame_bounds`; see there."""
    arm_lengths, base, anchors = geometry[0], geometry[1], geometry[2]
    angle_index = layout[4]
    p, size, n_links = arm_lengths.size, sigma.size, layout[0].size
    n_ranged = n_links + layout[2].size
    n = p + 1
    joints, moved = np.empty((p, 3)), np.empty((p, 3, n))
    joints_at(psi, arm_lengths, base[0], pivot_offset, joints)
    joint_jacobian_at(psi, arm_lengths, pivot_offset, moved)
    rows = np.zeros((size, n))
    for r in range(size):
        if r < n_ranged:
            range_row(r, layout, anchors, joints, moved, 1.0, rows[r])
        else:
            rows[r, angle_index[r - n_ranged]] = 1.0
    scaled = rows / sigma.reshape(-1, 1)
    information = scaled.T @ scaled
    links = rows[:n_links].copy()
    unknown, unknown_joint = np.full((n, n), np.inf), np.full((p, 3, 3), np.inf)
    if not np.all(np.isfinite(information)):
        return UNBOUNDED, unknown, unknown_joint, unknown, unknown_joint, links
    values, vectors = np.linalg.eigh(information)
    if not values[0] > DETERMINED * values[-1]:
        return UNBOUNDED, unknown, unknown_joint, unknown, unknown_joint, links
    random = (vectors / values) @ vectors.T
    random_joint = _joint_covariance(moved, random)
    # The poorly controlled links: what leaving each out would add (uncontrolled_covariance).
    link_scaled = np.ascontiguousarray(scaled[:n_links])
    through = link_scaled @ random
    added = np.zeros((n, n))
    for i in range(n_links):
        redundancy = 1.0 - np.dot(through[i], link_scaled[i])
        if redundancy < floor:
            added += np.outer(through[i], through[i]) / max(redundancy, LEAST_REDUNDANCY)
    if design.shape[0]:                         # the common bias (bias_covariance)
        mapped = random @ (link_scaled / sigma[:n_links].reshape(-1, 1)).T
        shifted = mapped @ design
        added += shifted @ common @ shifted.T
    if not np.any(added != 0.0):
        return RANDOM_ONLY, random, random_joint, random, random_joint, links
    total = random + added
    return WIDENED, random, random_joint, total, _joint_covariance(moved, total), links


def frame_bounds(model, residuals, psi, common, floor):
    """
    Return :func:`~epp_ros.core.model.bounds.frame_bounds`' arrays, compiled.

    ``(state, random covariance, random joint covariance, total covariance, total joint
    covariance, link rows)``; ``state`` one of :data:`UNBOUNDED`, :data:`RANDOM_ONLY`,
    :data:`WIDENED`.
    """
    design, covariance = (np.zeros((0, 0)), np.zeros((0, 0))) if common is None else common
    geometry = (plain(model.arm_lengths), plain(model.base).reshape(1, 3),
                plain(model.anchors))
    return _bounds(plain(psi), geometry, float(model.pivot_offset), residuals.layout,
                   plain(residuals.sigma), plain(design), plain(covariance), float(floor))


def compile_now():
    """Compile :func:`frame_bounds`' kernel, with and without the common bias, on one link."""
    empty = np.zeros(0, dtype=np.int64)
    layout = (np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), empty, empty, empty)
    geometry = (np.ones(1), np.zeros((1, 3)), np.ones((1, 3)))
    for design, common in ((np.zeros((0, 0)), np.zeros((0, 0))),
                           (np.ones((1, 2)), np.eye(2))):
        _bounds(np.zeros(2), geometry, 0.0, layout, np.ones(1), design, common, 0.3)
