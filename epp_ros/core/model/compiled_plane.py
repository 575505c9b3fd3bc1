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
The plane's slew and the tags in it fitted to the ranges, compiled: the same Gauss-Newton.

``plane.fit_plane_to_ranges`` predicts the plane every warm CEPP frame solves in: a few
Gauss-Newton steps on some thirty ranges, each step some twenty-five numpy calls on arrays
that small (issue #30). This is the same arithmetic compiled by numba; the numpy function
stays the reference and the path taken without numba or with ``EPP_ROS_COMPILED=0``
(``solvers.compiled``).
"""
import math

from epp_ros.core.solvers.compiled import compiled, plain
import numpy as np

__all__ = ['compile_now', 'fit_plane_to_ranges']


@compiled
def _rows(coords, ranges, anchors, base, slew, pivot, arm_lengths):
    """Return the Gauss-Newton rows: Jacobian (p m [+ p], 1 + 2 p), residuals at ``slew``."""
    p, m = ranges.shape
    with_sections = arm_lengths.size > 0
    n_rows = p * m + (p if with_sections else 0)
    jacobian = np.zeros((n_rows, 1 + 2 * p))
    residual = np.zeros(n_rows)
    cos, sin = math.cos(slew), math.sin(slew)
    for k in range(p):
        point = (base[0] + coords[k, 0] * cos, base[1] + coords[k, 0] * sin, coords[k, 1])
        for j in range(m):
            if not np.isfinite(ranges[k, j]):
                continue
            gap = (point[0] - anchors[j, 0], point[1] - anchors[j, 1],
                   point[2] - anchors[j, 2])
            distance = max(math.sqrt(gap[0] ** 2 + gap[1] ** 2 + gap[2] ** 2), 1e-9)
            unit = (gap[0] / distance, gap[1] / distance, gap[2] / distance)
            row = k * m + j
            jacobian[row, 0] = (unit[0] * -sin + unit[1] * cos) * coords[k, 0]
            jacobian[row, 1 + 2 * k] = unit[0] * cos + unit[1] * sin
            jacobian[row, 2 + 2 * k] = unit[2]
            residual[row] = distance - ranges[k, j]
    if with_sections:           # plane._with_sections
        for k in range(p):
            start = pivot if k == 0 else coords[k - 1]
            section = (coords[k, 0] - start[0], coords[k, 1] - start[1])
            length = max(math.sqrt(section[0] ** 2 + section[1] ** 2), 1e-9)
            row = p * m + k
            jacobian[row, 1 + 2 * k] = section[0] / length
            jacobian[row, 2 + 2 * k] = section[1] / length
            if k > 0:
                jacobian[row, 2 * k - 1] = -section[0] / length
                jacobian[row, 2 * k] = -section[1] / length
            residual[row] = length - arm_lengths[k]
    return jacobian, residual


@compiled
def _fit(coords, ranges, anchors, base, slew, pivot, arm_lengths, max_iter, tol):
    """Compiled :func:`fit_plane_to_ranges` (``arm_lengths`` empty: none)."""
    coords = coords.copy()
    p = coords.shape[0]
    for _ in range(max_iter):
        jacobian, residual = _rows(coords, ranges, anchors, base, slew, pivot, arm_lengths)
        normal = jacobian.T @ jacobian
        ridge = 1e-9 + 1e-9 * np.trace(normal)
        for i in range(normal.shape[0]):
            normal[i, i] += ridge
        gradient = jacobian.T @ residual
        if np.all(np.isfinite(normal)) and np.all(np.isfinite(gradient)):
            step = -np.linalg.solve(normal, gradient)
        else:                   # numpy's solve passes NaN on; numba's would raise
            step = np.full(gradient.size, np.nan)
        slew += step[0]
        for k in range(p):
            coords[k, 0] += step[1 + 2 * k]
            coords[k, 1] += step[2 + 2 * k]
        if abs(step[0]) <= tol:
            break
    return slew, coords


def fit_plane_to_ranges(coords, ranges, anchors, base, slew, pivot=None, arm_lengths=None,
                        max_iter=5, tol=1e-9):
    """Return ``plane.fit_plane_to_ranges``'s (slew, coords), compiled; its arguments."""
    sections = np.zeros(0) if arm_lengths is None else arm_lengths
    pivot = np.zeros(2) if pivot is None else pivot
    slew, coords = _fit(plain(coords), plain(ranges), plain(anchors), plain(base), float(slew),
                        plain(pivot), plain(sections), int(max_iter), float(tol))
    return float(slew), coords


def compile_now():
    """Compile :func:`fit_plane_to_ranges` (or load it from numba's cache)."""
    fit_plane_to_ranges(np.array([[1.0, 1.0]]), np.array([[1.5]]), np.zeros((1, 3)),
                        np.zeros(3), 0.0, np.zeros(2), np.ones(1), 1)
