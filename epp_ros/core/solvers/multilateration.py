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
Single-point localisation from anchor ranges: SR-LS (Beck, Stoica & Li, IEEE TSP 56, 2008).

SR-LS minimises the squared-range residuals ``sum_j (||x - a_j||^2 - r_j^2)^2``. With
``y = (x, ||x||^2)`` this is a least-squares problem under one quadratic equality, a
generalized trust-region subproblem whose global minimiser is found by bisection on a
scalar multiplier.
"""
import numpy as np

__all__ = ['srls', 'intersect_spheres', 'cold_start_guess']


def srls(anchors, ranges, *, tol=1e-12, max_iter=200):
    """
    Global minimiser of the squared-range least-squares criterion.

    Parameters
    ----------
    anchors : ndarray, shape (m, d)
        Anchor positions, metres; they must affinely span R^d (m >= d + 1).
    ranges : ndarray, shape (m,)
        Measured distances to the anchors, metres.
    tol : float
        Relative tolerance of the constraint and of the bisection on the multiplier.
    max_iter : int
        Bisection steps at most.

    Returns
    -------
    position : ndarray, shape (d,) or None
        None when the anchors do not span R^d (the problem then has no unique solution).

    """
    anchors = np.asarray(anchors, dtype=float)
    ranges = np.asarray(ranges, dtype=float)
    m, d = anchors.shape
    if m < d + 1:
        return None
    # Work relative to the anchors' centroid: better conditioned, same minimiser.
    centre = anchors.mean(axis=0)
    local = anchors - centre
    a = np.hstack([-2.0 * local, np.ones((m, 1))])
    b = ranges ** 2 - np.sum(local ** 2, axis=1)
    ata = a.T @ a
    atb = a.T @ b
    if np.linalg.cond(ata) > 1e12:
        return None
    quad = np.diag(np.r_[np.ones(d), 0.0])       # D
    lin = np.r_[np.zeros(d), -0.5]                # f

    def solution(lam):
        return np.linalg.solve(ata + lam * quad, atb - lam * lin)

    def constraint(y):
        return y[:d] @ y[:d] + 2.0 * lin @ y        # ||x||^2 - t, decreasing in lambda

    # A^T A + lam D is positive definite for lam > -1 / lambda_max(A^T A^-1/2 D A^T A^-1/2).
    chol = np.linalg.cholesky(ata)
    inv_chol = np.linalg.inv(chol)
    lam_max = np.linalg.eigvalsh(inv_chol @ quad @ inv_chol.T).max()
    lower = -1.0 / lam_max
    y = solution(0.0)
    if abs(constraint(y)) <= tol * max(1.0, y[d]):
        return y[:d] + centre
    if constraint(y) > 0:
        low, high = 0.0, 1.0
        while constraint(solution(high)) > 0 and high < 1e20:
            high *= 2.0
    else:
        # The root lies in (lower, 0); the constraint tends to +inf as lambda -> lower.
        high, gap = 0.0, -0.5 * lower
        low = lower + gap
        while constraint(solution(low)) < 0 and gap > 1e-15 * max(1.0, -lower):
            gap *= 0.5
            low = lower + gap
    for _ in range(max_iter):
        mid = 0.5 * (low + high)
        if constraint(solution(mid)) > 0:
            low = mid
        else:
            high = mid
        if high - low <= tol * max(1.0, abs(mid)):
            break
    return solution(0.5 * (low + high))[:d] + centre


def intersect_spheres(centres, radii):
    """
    Both intersection points of three spheres (trilateration).

    Parameters
    ----------
    centres : ndarray, shape (3, 3)
        One sphere centre per row, metres.
    radii : ndarray, shape (3,)
        Their radii, metres.

    Returns
    -------
    points : ndarray, shape (2, 3), or None when the centres are collinear
        The two mirror solutions about the centres' plane, the higher z first. Where noise
        keeps the spheres from meeting, both are the point of the plane nearest them.

    """
    centres = np.asarray(centres, dtype=float)
    r1, r2, r3 = np.asarray(radii, dtype=float)
    base = centres[0]
    ex = centres[1] - base
    d = np.linalg.norm(ex)
    if d <= 1e-9:
        return None
    ex = ex / d
    offset = centres[2] - base
    i = ex @ offset
    ey = offset - i * ex
    j = np.linalg.norm(ey)
    if j <= 1e-9 * max(d, 1.0):
        return None
    ey = ey / j
    ez = np.cross(ex, ey)
    x = (r1 ** 2 - r2 ** 2 + d ** 2) / (2 * d)
    y = (r1 ** 2 - r3 ** 2 + i ** 2 + j ** 2) / (2 * j) - i * x / j
    z = np.sqrt(max(r1 ** 2 - x ** 2 - y ** 2, 0.0))
    points = base + x * ex + y * ey + np.array([[z], [-z]]) * ez
    return points[np.argsort(-points[:, 2])]


def cold_start_guess(model, ranges):
    """
    Joint positions from this frame's ranges alone, to seed a solver without a previous pose.

    Each tag is located by SR-LS from its anchor ranges; a tag with too few of them also uses
    its already located neighbours (or the base pivot) as spheres of radius the section
    length, repeated outward until nothing more can be located. Tags still unlocated take
    the position of the nearest located joint along the chain; they only seed the solver.

    Returns
    -------
    joints : ndarray, shape (p, 3), or None when no tag can be located.

    """
    p = model.n_sections
    lengths = model.arm_lengths
    joints = np.full((p, 3), np.nan)

    def neighbour_spheres(k):
        centres, radii = [], []
        # A pivot off the slew axis moves with the unknown slew: no sphere around it.
        inner = (model.base if model.pivot_offset == 0.0 else np.full(3, np.nan)) if k == 0 \
            else joints[k - 1]
        if np.isfinite(inner[0]):
            centres.append(inner)
            radii.append(lengths[k])
        if k + 1 < p and np.isfinite(joints[k + 1, 0]):
            centres.append(joints[k + 1])
            radii.append(lengths[k + 1])
        return centres, radii

    for use_neighbours in (False, True):
        progress = True
        while progress:
            progress = False
            for k in np.flatnonzero(~np.isfinite(joints[:, 0])):
                valid = np.isfinite(ranges[k])
                centres, radii = neighbour_spheres(k) if use_neighbours else ([], [])
                centres = np.vstack([model.anchors[valid]] + [np.reshape(centres, (-1, 3))])
                radii = np.concatenate([ranges[k, valid], radii])
                position = _locate(centres, radii, allow_three=use_neighbours)
                if position is not None:
                    joints[k] = position
                    progress = use_neighbours
    located = np.flatnonzero(np.isfinite(joints[:, 0]))
    if located.size == 0:
        return None
    for k in np.setdiff1d(np.arange(p), located):
        joints[k] = joints[located[np.argmin(np.abs(located - k))]]
    return joints


def _locate(centres, radii, allow_three):
    """Return a point at the given distances from distinct centres; the upper one if ambiguous."""
    _, first = np.unique(np.round(centres, 9), axis=0, return_index=True)
    first = np.sort(first)
    centres, radii = centres[first], radii[first]
    position = srls(centres, radii) if radii.size >= 4 else None
    if position is None and allow_three and radii.size >= 3:
        candidates = intersect_spheres(centres[:3], radii[:3])
        position = None if candidates is None else candidates[0]
    return position
