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

__all__ = ['srls', 'intersect_spheres']


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
