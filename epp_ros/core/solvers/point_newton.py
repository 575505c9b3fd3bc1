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
The rank-r nearest-EDM problem in the points, and Newton's method on it.

Once an EDM of rank r is reached, ``D = D(X)`` for points ``X`` (n, r) and the problem is::

    min  f(X) = 1/2 ||H o (D(X) - G)||^2   s.t.  |x_a - x_b|^2 = G_ab  for the fixed pairs

a small smooth least-squares problem with quadratic equality constraints. Its first-order
(KKT) residual is the stopping rule of :func:`~epp_ros.core.solvers.nedm.nearest_edm`. The
penalty method's MM map converges on it linearly, one weighted projection per step;
Gauss-Newton steps with the constraints linearised (SQP), each followed by a minimum-norm
restoration onto the constraints, converge at a rate set by the residuals, in a few steps
of a few small dense solves each. ``nearest_edm`` takes them once its iterates are of rank
r: the penalty method chooses the basin, Newton's method finishes in it.
"""
import numpy as np
from scipy.linalg import lapack

__all__ = ['PointProblem']


def _least_squares(matrix, rhs):
    """
    Minimum-norm least-squares solution of ``matrix x = rhs``, (m, k) and (m,) -> (k,).

    LAPACK ``dgelsy`` (complete orthogonal factorisation) directly: ``numpy.linalg.lstsq``
    costs three times as much on these matrices of a few dozen rows, and the fixed pairs
    are often redundant (rank-deficient).
    """
    m, k = matrix.shape
    if not m or not k:
        return np.zeros(k)
    workspace = int(lapack.dgelsy_lwork(m, k, 1, 1e-13)[0])
    rhs = np.concatenate([rhs, np.zeros(max(k - m, 0))])
    _, solution, _, _, info = lapack.dgelsy(matrix, rhs, np.zeros(k, np.int32), 1e-13,
                                            workspace)
    if info != 0:
        raise np.linalg.LinAlgError(f'dgelsy failed (info={info})')
    return solution[:k]


class PointProblem:
    """
    ``min f(X)`` subject to the fixed distances, in the scaled units of ``nearest_edm``.

    Parameters
    ----------
    goal : ndarray, shape (n, n)
        G, symmetric.
    sq_weights : ndarray, shape (n, n)
        H o H, symmetric, zero diagonal.
    fixed_pairs : ndarray of int, shape (k, 2)
        The pairs ``(a, b)``, ``a < b``, whose squared distance is held to ``G_ab``.

    """

    #: Restoration steps after each Newton step at most: the constraints are quadratic, so
    #: each squares the violation (a step's O(|step|^2)) until round-off.
    RESTORATION_STEPS = 6
    #: Violation of a fixed squared distance counted as round-off (scaled units: of 1).
    ROUND_OFF = 1e-14
    #: Violation a kept step may leave: far below any tolerance of ``nearest_edm``.
    FEASIBLE = 1e-12
    #: Levenberg-Marquardt damping, relative to the largest diagonal of J^T J: the rigid
    #: motions leave f unchanged, and the damping takes them out of each step.
    INITIAL_DAMPING = 1e-9
    #: Damping beyond which a step is not tried: f does not decrease along any direction the
    #: model sees (at a minimum to round-off, or far outside the model's reach).
    MAX_DAMPING = 1e3

    def __init__(self, goal, sq_weights, fixed_pairs):
        self.goal, self.sq_weights = goal, sq_weights
        self.first, self.second = np.nonzero(np.triu(sq_weights, 1) > 0)
        # f = 1/2 sum over both triangles: sqrt(2) H on each pair once.
        self.root_weights = np.sqrt(2.0 * sq_weights[self.first, self.second])
        self.goal_pairs = goal[self.first, self.second]
        self.fixed_first, self.fixed_second = fixed_pairs[:, 0], fixed_pairs[:, 1]
        self.fixed_goal = goal[self.fixed_first, self.fixed_second]
        self.max_sq_weight = max(float(sq_weights.max(initial=0.0)), 1e-300)

    @staticmethod
    def _pair_jacobian(points, first, second):
        """Gradients of ``|x_a - x_b|^2`` for the pairs ``(first, second)``, rows, (k, n r)."""
        difference = 2.0 * (points[first] - points[second])
        rows = np.arange(first.size)
        jacobian = np.zeros((first.size,) + points.shape)
        jacobian[rows, first] = difference
        jacobian[rows, second] = -difference
        return jacobian.reshape(first.size, points.size)

    @staticmethod
    def _pair_distances(points, first, second):
        difference = points[first] - points[second]
        return np.einsum('ij,ij->i', difference, difference)

    def residuals(self, points):
        """Return ``sqrt(2) H_ab (|x_a - x_b|^2 - G_ab)`` over the weighted pairs (f = |r|^2/2)."""
        return self.root_weights * (self._pair_distances(points, self.first, self.second)
                                    - self.goal_pairs)

    def objective(self, points):
        """Return ``f(X)``."""
        residuals = self.residuals(points)
        return 0.5 * float(residuals @ residuals)

    def violations(self, points):
        """Return ``|x_a - x_b|^2 - G_ab`` over the fixed pairs, (k,)."""
        return (self._pair_distances(points, self.fixed_first, self.fixed_second)
                - self.fixed_goal)

    def constraint_jacobian(self, points):
        """Return the gradients of the fixed pairs' squared distances, rows, (k, n r)."""
        return self._pair_jacobian(points, self.fixed_first, self.fixed_second)

    def stationarity(self, points):
        """
        Return the relative KKT residual at ``points`` (n, r).

        ``|grad f(X) + J_c(X)^T mu| / (4 max(H o H) |X - mean X|_F)`` with the least-squares
        multipliers ``mu`` (``grad f(X) = 4 L(H o H o (D - G)) X``, ``L(S) = diag(S 1) - S``),
        or the largest violation of a fixed distance when that is larger: a point that is
        not feasible is not stationary. Free of the units of G and the weights' scale.
        """
        centred = points - points.mean(axis=0)
        distances = np.sum((centred[:, None, :] - centred[None, :, :]) ** 2, axis=2)
        stress = self.sq_weights * (distances - self.goal)
        laplacian = np.diag(stress.sum(axis=1)) - stress
        gradient = (4.0 * laplacian @ centred).ravel()
        infeasible = 0.0
        if self.fixed_first.size:
            infeasible = float(np.max(np.abs(self.violations(centred))))
            jacobian = self.constraint_jacobian(centred).T
            gradient = gradient - jacobian @ _least_squares(jacobian, gradient)
        size = 4.0 * self.max_sq_weight * np.linalg.norm(centred)
        return max(float(np.linalg.norm(gradient) / size) if size > 0 else 0.0, infeasible)

    def _restored(self, points):
        """
        Return ``points`` moved the least onto the fixed distances (Gauss-Newton).

        And the largest violation left (0 without fixed pairs).
        """
        violation = 0.0
        for attempt in range(self.RESTORATION_STEPS + 1 if self.fixed_first.size else 0):
            violations = self.violations(points)
            violation = float(np.max(np.abs(violations)))
            if not violation > self.ROUND_OFF or attempt == self.RESTORATION_STEPS:
                break
            step = _least_squares(self.constraint_jacobian(points), -violations)
            points = points + step.reshape(points.shape)
        return points, violation

    def _step(self, points, damping):
        """Return the damped Gauss-Newton step with the constraints linearised, (n, r)."""
        jacobian = (self._pair_jacobian(points, self.first, self.second)
                    * self.root_weights[:, None])
        normal = jacobian.T @ jacobian
        size = normal.shape[0]
        scale = max(float(normal.diagonal().max(initial=0.0)), 1e-300)
        normal.flat[::size + 1] += damping * scale
        gradient = jacobian.T @ self.residuals(points)
        constraints = self.constraint_jacobian(points)
        k = constraints.shape[0]
        # Redundant fixed pairs (more known points than a rigid body has freedoms) make the
        # KKT matrix singular: a small negative block keeps it quasi-definite.
        kkt = np.block([[normal, constraints.T],
                        [constraints, -1e-12 * scale * np.eye(k)]])
        solution = np.linalg.solve(kkt, -np.concatenate([gradient, self.violations(points)]))
        return solution[:size].reshape(points.shape)

    def refine(self, points, tol, max_steps, stationarity=None):
        """
        Newton steps from ``points`` (n, r) until stationary to ``tol``.

        ``stationarity``: that of ``points``, when known.

        A step is kept when, restored onto the fixed distances, it decreases ``f``; else
        the damping grows tenfold and the step is tried again. A step the restoration
        cannot bring back within ``FEASIBLE`` (or the start's violation) is not kept: f can
        fall by leaving the constraints.

        Returns
        -------
        points : ndarray, shape (n, r)
            The last point kept (``points`` if none was).
        stationarity : float
            Its :meth:`stationarity`.
        steps : int
            Newton steps tried.

        """
        value = self.objective(points)
        if stationarity is None:
            stationarity = self.stationarity(points)
        feasible = max(self.FEASIBLE, float(np.max(np.abs(self.violations(points)),
                                                   initial=0.0)))
        damping, steps = self.INITIAL_DAMPING, 0
        while stationarity > tol and steps < max_steps and damping <= self.MAX_DAMPING:
            steps += 1
            try:
                trial, violation = self._restored(points + self._step(points, damping))
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial_value = self.objective(trial)
            if trial_value <= value * (1 + 1e-14) and violation <= feasible:
                points, value = trial, trial_value
                stationarity = self.stationarity(points)
                damping = max(damping / 10.0, self.INITIAL_DAMPING)
            else:
                damping *= 10.0
        return points, stationarity, steps
