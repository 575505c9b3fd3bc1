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
Newton's method in the points of a rank-r nearest-EDM problem, compiled: the same steps.

:class:`~epp_ros.core.solvers.point_newton.PointProblem` finishes every CEPP frame with a
few SQP steps on a problem of a dozen points, each step some sixty numpy and LAPACK calls
on matrices that small: the calls, not the arithmetic, are the time (issue #30). This
module does the same arithmetic compiled by numba: the same residuals, Hessian of the
Lagrangian made PSD, KKT system and restoration onto the fixed distances, damped by the
schedule of ``core.solvers.levenberg_marquardt`` (whose constants it imports). Its least
squares, eigendecomposition and LU are the numpy path's LAPACK routines (scipy's
``dgelsy``, ``dsyevd``, ``dgesv``), called from the compiled code: numba's own ``lstsq``
(``dgelsd``) cost four times ``dgelsy`` on these systems.

The numpy path stays the reference (the tests run both on the same problems) and is the
one taken where numba is not installed or ``EPP_ROS_COMPILED=0``
(:mod:`~epp_ros.core.solvers.compiled`). One thing it does not repeat: the damping is
retried on the Hessian of the step's start, built once per step, not once per trial.
"""
import ctypes
from typing import NamedTuple

from epp_ros.core.solvers.compiled import compiled, plain
from epp_ros.core.solvers.levenberg_marquardt import (DAMPING_FLOOR, FALL, GROWTH,
                                                      INITIAL_DAMPING, MAX_DAMPING)
from epp_ros.core.solvers.point_newton import PointProblem
import numba
import numpy as np

__all__ = ['compile_now', 'refine', 'stationarity']

#: The least-squares rank cut, as ``point_newton._least_squares``'s ``dgelsy``.
_RCOND = 1e-13


class _Lapack(NamedTuple):
    """
    The LAPACK routines of the numpy path, scipy's, as functions numba calls.

    They are passed to the kernels as arguments: numba does not cache a function that
    finds a C function in a global. Each returns LAPACK's ``info``; the kernels treat a
    failure as the numpy path treats its ``LinAlgError``.
    """

    dgelsy: object
    dsyevd: object
    dgesv: object

    @classmethod
    def load(cls):
        """Return the three routines from ``scipy.linalg.cython_lapack``."""
        def routine(name, n_arguments):
            address = numba.extending.get_cython_function_address(
                'scipy.linalg.cython_lapack', name)
            return ctypes.CFUNCTYPE(None, *[ctypes.c_void_p] * n_arguments)(address)
        return cls(routine('dgelsy', 13), routine('dsyevd', 11), routine('dgesv', 8))


@compiled
def _fortran_copy(matrix):
    """
    Return a copy of ``matrix`` in column order, for LAPACK to overwrite.

    Always a copy: ``asfortranarray`` hands over an array already in column order (a
    transpose) as it is, and LAPACK would overwrite the caller's.
    """
    copy = np.empty((matrix.shape[1], matrix.shape[0])).T
    copy[:, :] = matrix
    return copy


@compiled
def _least_squares(matrix, rhs, lapack):
    """
    Minimum-norm least squares ``matrix x = rhs``, (m, k) and (m,): ``x`` (k,) and success.

    ``point_newton._least_squares``'s LAPACK call, ``dgelsy``.
    """
    m, k = matrix.shape
    if m == 0 or k == 0:
        return np.zeros(k), True
    a = _fortran_copy(matrix)
    b = np.zeros(max(m, k))
    b[:m] = rhs
    #                    m  n  nrhs lda ldb   rank lwork info
    scalars = np.array([m, k, 1, m, b.size, 0, -1, 0], dtype=np.int32)
    pivots = np.zeros(k, dtype=np.int32)
    rcond = np.array([_RCOND])
    work = np.zeros(1)
    for _ in range(2):                  # the workspace's size, then the solution
        lapack.dgelsy(scalars[0:].ctypes, scalars[1:].ctypes, scalars[2:].ctypes, a.ctypes,
                      scalars[3:].ctypes, b.ctypes, scalars[4:].ctypes, pivots.ctypes,
                      rcond.ctypes, scalars[5:].ctypes, work.ctypes, scalars[6:].ctypes,
                      scalars[7:].ctypes)
        if scalars[7] != 0:
            break
        scalars[6] = int(work[0])
        work = np.zeros(scalars[6])
    return b[:k].copy(), scalars[7] == 0


@compiled
def _eigh(matrix, lapack):
    """
    Eigenvalues (ascending), eigenvectors (columns) of a symmetric ``matrix`` (n, n), success.

    ``edm.symmetric_eigh``'s call: ``dsyevd`` on the upper triangle, with scipy's workspace.
    """
    n = matrix.shape[0]
    vectors = _fortran_copy(matrix)
    values = np.zeros(n)
    flags = np.array([ord('V'), ord('U')], dtype=np.uint8)
    #                    n  lda    lwork               liwork     info
    scalars = np.array([n, n, 1 + 6 * n + 2 * n * n, 3 + 5 * n, 0], dtype=np.int32)
    work, iwork = np.zeros(scalars[2]), np.zeros(scalars[3], dtype=np.int32)
    lapack.dsyevd(flags[0:].ctypes, flags[1:].ctypes, scalars[0:].ctypes, vectors.ctypes,
                  scalars[1:].ctypes, values.ctypes, work.ctypes, scalars[2:].ctypes,
                  iwork.ctypes, scalars[3:].ctypes, scalars[4:].ctypes)
    return values, vectors, scalars[4] == 0


@compiled
def _solve(matrix, rhs, lapack):
    """Solution of the square system ``matrix x = rhs`` (LU, ``dgesv``) and success."""
    n = matrix.shape[0]
    a = _fortran_copy(matrix)
    b = rhs.copy()
    #                    n  nrhs lda ldb info
    scalars = np.array([n, 1, n, n, 0], dtype=np.int32)
    pivots = np.zeros(n, dtype=np.int32)
    lapack.dgesv(scalars[0:].ctypes, scalars[1:].ctypes, a.ctypes, scalars[2:].ctypes,
                 pivots.ctypes, b.ctypes, scalars[3:].ctypes, scalars[4:].ctypes)
    return b, scalars[4] == 0


@compiled
def _pair_distances(points, first, second):
    """Squared distances ``|x_a - x_b|^2`` of the pairs ``(first, second)``, (k,)."""
    out = np.empty(first.size)
    for i in range(first.size):
        total = 0.0
        for d in range(points.shape[1]):
            gap = points[first[i], d] - points[second[i], d]
            total += gap * gap
        out[i] = total
    return out


@compiled
def _pair_jacobian(points, first, second):
    """Gradients of the pairs' squared distances, rows, (k, n r)."""
    n, r = points.shape
    jacobian = np.zeros((first.size, n * r))
    for i in range(first.size):
        for d in range(r):
            difference = 2.0 * (points[first[i], d] - points[second[i], d])
            jacobian[i, first[i] * r + d] = difference
            jacobian[i, second[i] * r + d] = -difference
    return jacobian


@compiled
def _violations(points, problem):
    """``|x_a - x_b|^2 - G_ab`` over the fixed pairs, (k,)."""
    return (_pair_distances(points, problem.fixed_first, problem.fixed_second)
            - problem.fixed_goal)


@compiled
def _largest(values):
    """``max |values|``, 0 when empty, NaN when any is."""
    largest = 0.0
    for value in values:
        if np.isnan(value):
            return np.nan
        largest = max(largest, abs(value))
    return largest


@compiled
def _objective(points, problem):
    """Return ``f(X)``."""
    residuals = problem.root_weights * (
        _pair_distances(points, problem.first, problem.second) - problem.goal_pairs)
    return 0.5 * np.sum(residuals * residuals)


@compiled
def _squared_distances(points):
    """``edm.squared_distances``: from the Gram matrix, clipped at zero."""
    gram = points @ points.T
    n = points.shape[0]
    out = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            out[a, b] = max(gram[a, a] + gram[b, b] - 2.0 * gram[a, b], 0.0)
    return out


@compiled
def _laplacian(pair_weights, first, second, n):
    """Return ``L(W) = diag(W 1) - W`` (n, n) of weights on the pairs (first, second)."""
    weights = np.zeros((n, n))
    for i in range(first.size):
        weights[first[i], second[i]] = pair_weights[i]
    return _laplacian_of(weights + weights.T)


@compiled
def _stationarity(points, problem):
    """``PointProblem.stationarity``: the relative KKT residual at ``points`` (n, r)."""
    if not np.all(np.isfinite(points)):
        return np.inf
    r = points.shape[1]
    centred = points.copy()
    for d in range(r):
        centred[:, d] -= points[:, d].mean()
    stress = problem.sq_weights * (_squared_distances(centred) - problem.goal)
    gradient = (4.0 * _laplacian_of(stress) @ centred).ravel()
    infeasible = 0.0
    if problem.fixed_first.size:
        infeasible = _largest(_violations(centred, problem))
        jacobian = np.ascontiguousarray(
            _pair_jacobian(centred, problem.fixed_first, problem.fixed_second).T)
        multipliers, solved = _least_squares(jacobian, gradient, problem.lapack)
        if not solved:
            return np.inf
        gradient = gradient - jacobian @ multipliers
    size = 4.0 * problem.max_sq_weight * np.sqrt(np.sum(centred * centred))
    norm = np.sqrt(np.sum(gradient * gradient))
    return max(norm / size if size > 0 else 0.0, infeasible)


@compiled
def _laplacian_of(weights):
    """Return ``diag(W 1) - W`` of a full matrix ``weights`` (n, n)."""
    laplacian = -weights
    for a in range(weights.shape[0]):
        laplacian[a, a] += weights[a].sum()
    return laplacian


@compiled
def _restored(points, problem, constants):
    """``PointProblem._restored``: the least move onto the fixed distances, and success."""
    restoration_steps, round_off = int(constants[1]), constants[2]
    attempts = restoration_steps + 1 if problem.fixed_first.size else 0
    for attempt in range(attempts):
        violations = _violations(points, problem)
        if not _largest(violations) > round_off or attempt == restoration_steps:
            break
        step, solved = _least_squares(
            _pair_jacobian(points, problem.fixed_first, problem.fixed_second), -violations,
            problem.lapack)
        if not solved:
            return points, False
        points = points + step.reshape(points.shape)
    return points, True


@compiled
def _newton_system(points, problem):
    """
    Return the step's undamped pieces at ``points``: Hessian, gradient, constraints; success.

    ``PointProblem._restored_step`` up to the damping, with ``_newton_matrix``.
    """
    first, second, root_weights = problem.first, problem.second, problem.root_weights
    n, r = points.shape
    jacobian = _pair_jacobian(points, first, second)
    for i in range(first.size):
        jacobian[i] *= root_weights[i]
    residuals = root_weights * (_pair_distances(points, first, second) - problem.goal_pairs)
    gradient = jacobian.T @ residuals
    constraints = _pair_jacobian(points, problem.fixed_first, problem.fixed_second)
    least, solved = _least_squares(np.ascontiguousarray(constraints.T), gradient,
                                   problem.lapack)
    multipliers = -least
    stress = residuals * root_weights / 2.0
    curvature = (4.0 * _laplacian(stress, first, second, n)
                 + 2.0 * _laplacian(multipliers, problem.fixed_first, problem.fixed_second, n))
    eigenvalues, eigenvectors, decomposed = _eigh(curvature, problem.lapack)
    positive = (eigenvectors * np.maximum(eigenvalues, 0.0)) @ eigenvectors.T
    hessian = jacobian.T @ jacobian
    for a in range(n):
        for b in range(n):
            for d in range(r):
                hessian[a * r + d, b * r + d] += positive[a, b]
    return hessian, gradient, constraints, solved and decomposed


@compiled
def _damped_step(points, system, damping, problem, constants):
    """``PointProblem._restored_step`` from :func:`_newton_system`'s pieces; and success."""
    hessian, gradient, constraints, _ = system
    size, k = hessian.shape[0], constraints.shape[0]
    scale = 1e-300
    for i in range(size):
        scale = max(scale, hessian[i, i])
    kkt = np.zeros((size + k, size + k))
    kkt[:size, :size] = hessian
    for i in range(size):
        kkt[i, i] += damping * hessian[i, i] + constants[0] * scale
    kkt[:size, size:] = constraints.T
    kkt[size:, :size] = constraints
    for i in range(k):
        kkt[size + i, size + i] = -1e-12 * scale
    rhs = -np.concatenate((gradient, _violations(points, problem)))
    solution, solved = _solve(kkt, rhs, problem.lapack)
    moved, restored = _restored(points + solution[:size].reshape(points.shape), problem,
                                constants)
    return (moved - points).ravel(), solved and restored


@compiled
def _trial_cost(points, problem, feasible):
    """``PointProblem.refine``'s cost: f where the fixed distances hold to ``feasible``."""
    if not _largest(_violations(points, problem)) <= feasible:
        return np.inf
    value = _objective(points, problem)
    return value if np.isfinite(value) else np.inf


@compiled
def _refine(points, problem, tol, max_steps, reached, feasible, constants):
    """Compiled :func:`refine` from a finite ``points`` not yet stationary."""
    x = points.copy()
    cost = _trial_cost(x, problem, feasible)
    damping = INITIAL_DAMPING
    for iteration in range(1, max_steps + 1):
        system = _newton_system(x, problem)
        while True:
            # A failed factorisation ends the steps (the numpy path's LinAlgError).
            step = np.zeros(x.size)
            if system[3]:
                step, solved = _damped_step(x, system, damping, problem, constants)
                if not solved:
                    step = np.zeros(x.size)
            trial = x + step.reshape(x.shape)
            trial_cost = _trial_cost(trial, problem, feasible)
            if trial_cost <= cost or damping > MAX_DAMPING:
                break
            damping *= GROWTH
        if trial_cost > cost:               # no step lowers f: a minimum
            return x, reached, iteration
        stalled = cost - trial_cost <= 0.0
        x, cost = trial, trial_cost
        damping = max(damping / FALL, DAMPING_FLOOR)
        reached = _stationarity(x, problem)
        if reached <= tol or stalled or _largest(step) <= 0.0:
            return x, reached, iteration
    return x, reached, max_steps


#: The LAPACK routines the kernels call.
_LAPACK = _Lapack.load()


class _Problem(NamedTuple):
    """A ``PointProblem``'s arrays as the kernels take them, and the LAPACK routines."""

    goal: np.ndarray
    sq_weights: np.ndarray
    first: np.ndarray
    second: np.ndarray
    root_weights: np.ndarray
    goal_pairs: np.ndarray
    fixed_first: np.ndarray
    fixed_second: np.ndarray
    fixed_goal: np.ndarray
    max_sq_weight: float
    lapack: _Lapack


def _problem(point_problem):
    """Return a ``PointProblem`` as a :class:`_Problem`."""
    pp = point_problem
    return _Problem(pp.goal, pp.sq_weights, pp.first, pp.second, pp.root_weights,
                    pp.goal_pairs, plain(pp.fixed_first, np.int64),
                    plain(pp.fixed_second, np.int64), pp.fixed_goal,
                    float(pp.max_sq_weight), _LAPACK)


def _constants(point_problem):
    """Return the ridge's and the restoration's constants of a ``PointProblem``."""
    return np.array([point_problem.RIDGE, point_problem.RESTORATION_STEPS,
                     point_problem.ROUND_OFF], dtype=float)


def stationarity(point_problem, points):
    """Return :meth:`PointProblem.stationarity` at ``points`` (n, r), compiled."""
    return float(_stationarity(plain(points),
                               _problem(point_problem)))


def refine(point_problem, points, tol, max_steps, stationarity, feasible):
    """
    Return :meth:`PointProblem.refine` from finite ``points`` not stationary to ``tol``.

    ``stationarity``: that of ``points``; ``feasible``: the violation a kept step may
    leave. Returns the points kept, their stationarity and the Newton steps taken.
    """
    x, reached, steps = _refine(plain(points),
                                _problem(point_problem), float(tol), int(max_steps),
                                float(stationarity), float(feasible),
                                _constants(point_problem))
    return x, float(reached), int(steps)


def compile_now():
    """Compile :func:`refine` and :func:`stationarity` (or load them from numba's cache)."""
    goal = np.array([[0.0, 1.0, 2.0], [1.0, 0.0, 1.0], [2.0, 1.0, 0.0]])
    problem = PointProblem(goal, (goal > 0).astype(float), np.array([[0, 1]]))
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    refine(problem, points, 1e-9, 2, stationarity(problem, points), 1e-12)
