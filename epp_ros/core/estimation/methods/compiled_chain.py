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
The chain's and the tracker's Levenberg–Marquardt fit, compiled: the same costs and steps.

A frame's fit is a few dozen residuals in p + 1 unknowns (the tracker's: 2 (p + 1)). In
numpy each step is some forty array operations on arrays that small, and their calls, not
their arithmetic, are the time (issue #30). This module does the same arithmetic in one
function compiled by numba, from the same inputs: the boom's geometry (compiled in
``core.model.compiled_boom``), the rows of ``Residuals``, the constants of the NLOS loss
(``LinkLoss``, whose formulas ``compiled_nlos.link_loss`` repeats) and the damping schedule
of ``core.solvers.levenberg_marquardt``, whose constants it imports.

The tracker's update is the same fit in the angles and their rates, each tag's ranges at
the time it ranged, under the prediction's Gaussian prior (``TrackMethod._evaluate``).
The numpy paths of :class:`~epp_ros.core.estimation.methods.chain.ChainMethod` and
``TrackMethod`` stay the reference: the tests fit the same frames both ways and compare.
They are the paths taken where numba is not installed, or with ``EPP_ROS_COMPILED=0`` in
the environment; this module (and numba, about 0.4 s) is imported at the first compiled
fit only. The first fit on a machine compiles (some 10 s, once: numba caches it beside
this file); the compiled function releases the GIL, so a node's executor thread runs
while its worker fits.
"""
import math

from epp_ros.core.model.compiled_boom import joint_jacobian_at, joints_at, range_row
from epp_ros.core.model.compiled_nlos import link_loss, loss_terms
from epp_ros.core.solvers.compiled import compiled, plain
from epp_ros.core.solvers.levenberg_marquardt import (DAMPING_FLOOR, FALL, GROWTH,
                                                      INITIAL_DAMPING, MAX_DAMPING, RIDGE)
import numpy as np

__all__ = ['compile_now', 'cost', 'fit', 'loss_terms']


@compiled
def _boom_at_tags(x, geometry, ground, motion, joints, boom):
    """
    Fill ``boom`` (p, p, 3): every joint when each tag ranged, ``x``'s angles + delay rates.

    ``x`` is the angles (p + 1,), or the angles and their rates (2 (p + 1),) with
    ``motion[0]`` each tag's delay from the stamp (``Residuals.timed``); ``joints`` (p, 3)
    are those at the stamp.
    """
    n = geometry[0].size + 1
    for k in range(n - 1):
        if x.size > n:
            joints_at(x[:n] + motion[0][k] * x[n:], geometry[0], geometry[1][0], ground[0],
                      boom[k])
        else:                               # no rates: every tag ranged at the stamp
            boom[k] = joints


@compiled
def _evaluate(x, geometry, rows, measured, sigma, terms, ground, motion, joints, state):
    """
    Return the cost at ``x``; fill ``joints`` (at the stamp) and ``state``.

    ``state`` rows: scaled residuals, slopes, IRLS weights, ground depths. The chain's
    ``_evaluate`` and ``loss`` (ranges under the NLOS loss ``terms``, angles Gaussian, the
    ground); for the tracker's state of angles and rates, each tag's ranges when it ranged,
    and the prediction's Gaussian prior ``motion[1:]`` (mean, information; none when empty).
    """
    arm_lengths, anchors = geometry[0], geometry[2]
    tag, anchor, near, far, angle_index = rows[0], rows[1], rows[2], rows[3], rows[4]
    lowest_joint, ground_sigma = ground[1], ground[2]
    scaled, slope, weights, depth = state[0], state[1], state[2], state[3]
    p = arm_lengths.size
    joints_at(x[:p + 1], arm_lengths, geometry[1][0], ground[0], joints)
    boom = np.empty((p, p, 3))
    _boom_at_tags(x, geometry, ground, motion, joints, boom)
    n_links, n_tags = tag.size, near.size
    n_ranged = n_links + n_tags
    cost = 0.0
    for r in range(measured.size):
        if r < n_ranged:
            if r < n_links:
                a, b = boom[tag[r], tag[r]], anchors[anchor[r]]
            else:
                at = boom[near[r - n_links]]
                a, b = at[near[r - n_links]], at[far[r - n_links]]
            distance = math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)
            scaled[r] = (distance - measured[r]) / sigma[r]
            if terms.shape[0]:
                c, excess_slope = link_loss(-scaled[r], terms, r)
                slope[r] = -excess_slope
            else:
                c, slope[r] = 0.5 * scaled[r] ** 2, scaled[r]
        else:
            scaled[r] = _wrap(x[angle_index[r - n_ranged]] - measured[r]) / sigma[r]
            c, slope[r] = 0.5 * scaled[r] ** 2, scaled[r]
        cost += c
        weights[r] = 1.0
        if abs(scaled[r]) > 1.0:
            weights[r] = min(max(slope[r] / scaled[r], 1e-3), 1.0)
    if motion[2].shape[0]:
        difference = _from_prior(x, motion[1])
        cost += 0.5 * (difference @ (motion[2] @ difference))
    for k in range(p):
        depth[k] = max(lowest_joint - joints[k, 2], 0.0) / ground_sigma
        cost += 0.5 * depth[k] ** 2
    return cost


@compiled
def _wrap(angle):
    """Return ``angle`` wrapped into [-pi, pi), as ``wrap_angle``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@compiled
def _from_prior(x, mean):
    """Return ``x - mean``, its angles (the first half) wrapped."""
    difference = x - mean
    for q in range(x.size // 2):
        difference[q] = _wrap(difference[q])
    return difference


@compiled
def _normal_equations(x, geometry, rows, sigma, ground, motion, joints, state, normal,
                      gradient):
    """Fill the IRLS ``normal`` matrix and ``gradient`` at ``x`` (the methods' own)."""
    arm_lengths, anchors = geometry[0], geometry[2]
    tag, near, angle_index = rows[0], rows[2], rows[4]
    pivot_offset, ground_sigma = ground[0], ground[2]
    slope, weights, depth = state[1], state[2], state[3]
    size, p = x.size, arm_lengths.size
    n = p + 1
    boom = np.empty((p, p, 3))
    _boom_at_tags(x, geometry, ground, motion, joints, boom)
    jacobian = np.empty((p, p, 3, n))        # tag k's time: every joint's
    stamp = np.empty((p, 3, n))
    joint_jacobian_at(x[:n], arm_lengths, pivot_offset, stamp)
    for k in range(p):
        if size > n:
            joint_jacobian_at(x[:n] + motion[0][k] * x[n:], arm_lengths, pivot_offset,
                              jacobian[k])
        else:                               # one time for every tag
            jacobian[k] = stamp
    normal[:] = 0.0
    gradient[:] = 0.0
    row = np.empty(size)
    n_links, n_tags = tag.size, near.size
    for r in range(sigma.size):
        row[:] = 0.0
        if r < n_links + n_tags:
            k = tag[r] if r < n_links else near[r - n_links]     # each tag at its time
            range_row(r, rows, anchors, boom[k], jacobian[k], sigma[r], row[:n])
            if size > n:
                row[n:] = row[:n] * motion[0][k]
        else:
            row[angle_index[r - n_links - n_tags]] = 1.0 / sigma[r]
        for q in range(size):
            gradient[q] += row[q] * slope[r]
            for s in range(size):
                normal[q, s] += row[q] * weights[r] * row[s]
    if motion[2].shape[0]:
        normal += motion[2]
        gradient += motion[2] @ _from_prior(x, motion[1])
    for k in range(p):
        if depth[k] > 0.0:
            for q in range(n):
                gradient[q] -= stamp[k, 2, q] / ground_sigma * depth[k]
                for s in range(n):
                    normal[q, s] += stamp[k, 2, q] * stamp[k, 2, s] / ground_sigma ** 2


@compiled
def _damped_step(normal, gradient, damping, step):
    """Fill ``step`` with ``-(normal + damping diag(diag + ridge))^-1 gradient`` (LU, pivoting)."""
    n = gradient.size
    system = normal.copy()
    for q in range(n):
        system[q, q] += damping * (normal[q, q] + RIDGE)
    step[:] = -gradient
    for col in range(n):
        pivot = col + np.argmax(np.abs(system[col:, col]))
        if pivot != col:
            for c in range(n):
                system[col, c], system[pivot, c] = system[pivot, c], system[col, c]
            step[col], step[pivot] = step[pivot], step[col]
        for r in range(col + 1, n):
            factor = system[r, col] / system[col, col]
            for c in range(col, n):
                system[r, c] -= factor * system[col, c]
            step[r] -= factor * step[col]
    for r in range(n - 1, -1, -1):
        total = step[r]
        for c in range(r + 1, n):
            total -= system[r, c] * step[c]
        step[r] = total / system[r, r]


@compiled
def _fit(start, geometry, rows, measured, sigma, terms, ground, motion, limits):
    """Compiled :func:`fit`; ``limits`` = (max_iter, tol, stall, damping_floor)."""
    max_iter, tol, stall, damping_floor = int(limits[0]), limits[1], limits[2], limits[3]
    n, p, size = start.size, geometry[0].size, measured.size
    x = start.copy()
    joints, trial_joints = np.empty((p, 3)), np.empty((p, 3))
    state, trial_state = np.empty((4, max(size, p))), np.empty((4, max(size, p)))
    normal, gradient, step = np.empty((n, n)), np.empty(n), np.empty(n)
    cost = _evaluate(x, geometry, rows, measured, sigma, terms, ground, motion, joints, state)
    damping = INITIAL_DAMPING
    iterations, converged = max_iter, False
    for iteration in range(1, max_iter + 1):
        _normal_equations(x, geometry, rows, sigma, ground, motion, joints, state, normal,
                          gradient)
        while True:
            _damped_step(normal, gradient, damping, step)
            trial = x + step
            trial_cost = _evaluate(trial, geometry, rows, measured, sigma, terms, ground,
                                   motion, trial_joints, trial_state)
            if trial_cost <= cost or damping > MAX_DAMPING:
                break
            damping *= GROWTH
        if trial_cost > cost:               # no step lowers the cost: a minimum
            iterations, converged = iteration, True
            break
        stalled = cost - trial_cost <= stall * max(abs(trial_cost), 1e-300)
        x, cost = trial, trial_cost
        joints, trial_joints = trial_joints, joints
        state, trial_state = trial_state, state
        damping = max(damping / FALL, damping_floor)
        if stalled or np.max(np.abs(step)) <= tol:
            iterations, converged = iteration, True
            break
    _normal_equations(x, geometry, rows, sigma, ground, motion, joints, state, normal,
                      gradient)
    return x, cost, state[0, :size].copy(), iterations, converged, normal


def fit(start, model, residuals, terms, lowest_joint, ground_sigma, max_iter, tol, stall,
        damping_floor=DAMPING_FLOOR, motion=None):
    """
    Fit a frame's chain by Levenberg–Marquardt from ``start``, compiled.

    Parameters
    ----------
    start : ndarray, shape (p + 1,) or (2 (p + 1),)
        Slew and pitches, radians; or those and their rates, rad/s (the tracker's state).
    model : BoomModel
        The boom and the anchors.
    residuals : Residuals
        The frame's rows, measured values and sigmas.
    terms : ndarray, shape (7, n_ranged) or (0, 0)
        The ranges' loss, :func:`loss_terms`.
    lowest_joint, ground_sigma : float
        The ground penalty, metres.
    max_iter : int
        Iterations at most.
    tol, stall, damping_floor : float
        As ``levenberg_marquardt``'s.
    motion : (ndarray, ndarray, ndarray), optional
        The tracker's: each tag's delay from the stamp (p,), seconds, and the prediction's
        mean and information (Gaussian prior on the state).

    Returns
    -------
    x : ndarray, shape of ``start``
    cost : float
    state : (ndarray, ndarray)
        The scaled residuals at ``x`` (size,), and the normal matrix there.
    iterations : int
    converged : bool

    """
    limits = np.array([max_iter, tol, stall, damping_floor], dtype=float)
    x, cost, scaled, iterations, converged, normal = _fit(
        np.array(start, dtype=float), *_problem(model, residuals, terms, lowest_joint,
                                                ground_sigma, motion), limits)
    return x, float(cost), (scaled, normal), int(iterations), bool(converged)


def cost(x, model, residuals, terms, lowest_joint, ground_sigma, motion=None):
    """Return the fit's cost at ``x``: :func:`fit`'s arguments, compiled."""
    return float(_cost(np.array(x, dtype=float),
                       *_problem(model, residuals, terms, lowest_joint, ground_sigma, motion)))


@compiled
def _cost(x, geometry, rows, measured, sigma, terms, ground, motion):
    """Compiled :func:`cost`."""
    p = geometry[0].size
    state = np.empty((4, max(measured.size, p)))
    return _evaluate(x, geometry, rows, measured, sigma, terms, ground, motion,
                     np.empty((p, 3)), state)


def _problem(model, residuals, terms, lowest_joint, ground_sigma, motion):
    """Return a frame's arguments of :func:`_fit` and :func:`_cost`, after the start."""
    geometry = (plain(model.arm_lengths), plain(model.base).reshape(1, 3),
                plain(model.anchors))
    ground = np.array([model.pivot_offset, lowest_joint, ground_sigma], dtype=float)
    if motion is None:
        motion = (np.zeros(model.n_sections), np.zeros(0), np.zeros((0, 0)))
    return (geometry, residuals.layout, plain(residuals.measured), plain(residuals.sigma),
            plain(terms), ground, tuple(plain(part) for part in motion))


def compile_now():
    """Compile the fit and the cost (or load them from numba's disk cache), on one link."""
    empty = np.zeros(0, dtype=np.int64)
    rows = (np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), empty, empty, empty)
    problem = ((np.ones(1), np.zeros((1, 3)), np.ones((1, 3))), rows, np.ones(1), np.ones(1),
               np.zeros((0, 0)), np.array([0.0, -1.0, 0.05]),
               (np.zeros(1), np.zeros(0), np.zeros((0, 0))))
    _fit(np.zeros(2), *problem, np.array([5.0, 1e-10, 1e-6, 1e-9]))
    _cost(np.zeros(2), *problem)
