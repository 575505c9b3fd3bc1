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
The boom's geometry compiled: the joints and their derivatives at the posture angles.

``BoomModel.forward_kinematics`` and ``BoomModel.joint_jacobian`` (``core.model.boom``) are
the reference; these repeat them, one posture at a time, for the compiled fits
(``estimation.methods.compiled_chain``) and bounds (``compiled_bounds``). Imported at
first use only (``solvers.compiled``).
"""
import math

from epp_ros.core.solvers.compiled import compiled

__all__ = ['joint_jacobian_at', 'joints_at', 'range_row']


@compiled
def joints_at(psi, arm_lengths, base, pivot_offset, joints):
    """Fill ``joints`` (p, 3) at angles ``psi``: ``BoomModel.forward_kinematics``."""
    cos_slew, sin_slew = math.cos(psi[0]), math.sin(psi[0])
    along, height = 0.0, 0.0
    for k in range(arm_lengths.size):
        along += arm_lengths[k] * math.cos(psi[1 + k])
        height += arm_lengths[k] * math.sin(psi[1 + k])
        reach = pivot_offset + along
        joints[k, 0] = base[0] + reach * cos_slew
        joints[k, 1] = base[1] + reach * sin_slew
        joints[k, 2] = base[2] + height


@compiled
def joint_jacobian_at(psi, arm_lengths, pivot_offset, jacobian):
    """Fill ``jacobian`` (p, 3, p + 1) at ``psi``: ``BoomModel.joint_jacobian``."""
    p = arm_lengths.size
    cos_slew, sin_slew = math.cos(psi[0]), math.sin(psi[0])
    jacobian[:] = 0.0
    along = 0.0
    for i in range(p):
        along += arm_lengths[i] * math.cos(psi[1 + i])
        reach = pivot_offset + along
        jacobian[i, 0, 0] = -reach * sin_slew
        jacobian[i, 1, 0] = reach * cos_slew
        rise = arm_lengths[i] * math.sin(psi[1 + i])
        for k in range(i, p):      # joint k moves with sections i <= k
            jacobian[k, 0, 1 + i] = -rise * cos_slew
            jacobian[k, 1, 1 + i] = -rise * sin_slew
            jacobian[k, 2, 1 + i] = arm_lengths[i] * math.cos(psi[1 + i])


@compiled
def range_row(r, layout, anchors, joints, moved, sigma, row):
    """
    Add range ``r``'s derivative over ``sigma`` to ``row`` (p + 1,): ``Residuals.rows``.

    ``layout`` as ``Residuals.layout``; ``r`` a tag-anchor or tag-tag range of it;
    ``joints`` (p, 3) and their derivatives ``moved`` (p, 3, p + 1) where the range's tag
    ranged.
    """
    tag, anchor, near, far = layout[0], layout[1], layout[2], layout[3]
    n_links = tag.size
    if r < n_links:
        k, other, b = tag[r], -1, anchors[anchor[r]]
    else:
        k, other = near[r - n_links], far[r - n_links]
        b = joints[other]
    a = joints[k]
    distance = max(math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2),
                   1e-12)
    for c in range(3):
        unit = (a[c] - b[c]) / distance / sigma
        for q in range(row.size):
            step = moved[k, c, q] - (moved[other, c, q] if other >= 0 else 0.0)
            row[q] += unit * step
