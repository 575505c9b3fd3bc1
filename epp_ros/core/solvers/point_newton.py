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
penalty method's MM map converges on it linearly, one weighted projection per step. Newton
steps with the constraints linearised (SQP; the Hessian of the Lagrangian is exact, as
everything is quadratic in the points), each followed by a minimum-norm restoration onto
the constraints and damped by the package's Levenberg-Marquardt loop, converge in a few
steps of a few small dense solves each. ``nearest_edm`` takes them once its iterates are
of rank r: the start or the penalty method chooses the basin, Newton's method finishes in it.
:meth:`PointProblem.refine` and :meth:`PointProblem.stationarity` run compiled where the
kernels are (``compiled_points``); this numpy code is their reference.
"""
from epp_ros.core.solvers.compiled import kernel
from epp_ros.core.solvers.edm import squared_distances, symmetric_eigh
from epp_ros.core.solvers.levenberg_marquardt import levenberg_marquardt
import numpy as np
from scipy.linalg import lapack

__all__ = ['PointProblem']

#: The compiled twin of :meth:`PointProblem.refine` and :meth:`PointProblem.stationarity`.
KERNEL = 'epp_ros.core.solvers.compiled_points'


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
    #: Added to the Hessian's diagonal besides the damping, relative to its largest entry:
    #: the rigid motions leave f and the constraints unchanged.
    RIDGE = 1e-9

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
        not feasible is not stationary. Free of the units of G and the weights' scale; inf
        at points that are not finite.
        """
        if not np.all(np.isfinite(points)):
            return np.inf
        if kernel(KERNEL) is not None:
            return kernel(KERNEL).stationarity(self, points)
        centred = points - points.mean(axis=0)
        distances = squared_distances(centred)
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

    def onto_fixed(self, points):
        """Return ``points`` (n, r) moved the least onto the fixed distances."""
        return self._restored(points)[0]

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

    @staticmethod
    def _laplacian(pair_weights, first, second, n):
        """Return ``L(W) = diag(W 1) - W`` (n, n) of weights on the pairs (first, second)."""
        weights = np.zeros((n, n))
        weights[first, second] = pair_weights
        weights += weights.T
        return np.diag(weights.sum(axis=1)) - weights

    def _newton_matrix(self, points, jacobian, residuals, gradient, constraints):
        """
        Return the Hessian of the Lagrangian ``f + mu^T c`` with its curvature made PSD.

        The residuals and the constraints are quadratic in the points, so their second
        derivatives are the Laplacians of the pairs: the Hessian is ``J^T J + C kron I_r``
        with ``C = 4 L(S) + 2 L(mu)``, the stresses ``S = H o H o (D - G)`` and the
        least-squares multipliers ``mu``. Gauss-Newton's ``J^T J`` alone over-steps where
        the residuals are large (ranges that fit no posture); far from a minimum C may have
        negative eigenvalues, which are dropped (a modified Newton method): near a minimum
        the step is Newton's, and it is always a descent direction for the damping to tune.
        """
        n, r = points.shape
        multipliers = -_least_squares(constraints.T, gradient)
        stress = residuals * self.root_weights / 2.0            # H^2 (d - G) on each pair
        curvature = (4.0 * self._laplacian(stress, self.first, self.second, n)
                     + 2.0 * self._laplacian(multipliers, self.fixed_first, self.fixed_second, n))
        eigenvalues, eigenvectors = symmetric_eigh(curvature)
        positive = (eigenvectors * np.maximum(eigenvalues, 0.0)) @ eigenvectors.T
        return jacobian.T @ jacobian + np.kron(positive, np.eye(r))

    def _step(self, points, damping):
        """
        Return Marquardt's damped Newton step, the constraints linearised, then restored.

        Returns the step (n r,) from ``points`` (n, r) to the restored point; zero when
        LAPACK fails (non-finite points), which ends the steps.
        """
        try:
            return self._restored_step(points, damping)
        except np.linalg.LinAlgError:
            return np.zeros(points.size)

    def _restored_step(self, points, damping):
        """Return :meth:`_step`, raising LinAlgError when a factorisation fails."""
        jacobian = (self._pair_jacobian(points, self.first, self.second)
                    * self.root_weights[:, None])
        residuals = self.residuals(points)
        gradient = jacobian.T @ residuals
        constraints = self.constraint_jacobian(points)
        hessian = self._newton_matrix(points, jacobian, residuals, gradient, constraints)
        size, k = hessian.shape[0], constraints.shape[0]
        scale = max(float(hessian.diagonal().max(initial=0.0)), 1e-300)
        # The rigid motions change nothing: the ridge holds them still.
        hessian.flat[::size + 1] += damping * hessian.diagonal() + self.RIDGE * scale
        # Redundant fixed pairs (more known points than a rigid body has freedoms) make the
        # KKT matrix singular: a small negative block keeps it quasi-definite.
        kkt = np.block([[hessian, constraints.T],
                        [constraints, -1e-12 * scale * np.eye(k)]])
        solution = np.linalg.solve(kkt, -np.concatenate([gradient, self.violations(points)]))
        restored, _ = self._restored(points + solution[:size].reshape(points.shape))
        return (restored - points).ravel()

    def refine(self, points, tol, max_steps, stationarity=None):
        """
        Newton steps from ``points`` (n, r) until stationary to ``tol``.

        ``stationarity``: that of ``points``, when known. The steps are damped by the
        package's Levenberg-Marquardt loop (:mod:`~epp_ros.core.solvers.levenberg_marquardt`):
        one is kept when, restored onto the fixed distances, it does not raise ``f``. A
        step the restoration cannot bring back within ``FEASIBLE`` (or the start's
        violation) is not kept: f can fall by leaving the constraints.

        Returns
        -------
        points : ndarray, shape (n, r)
            The last point kept (``points`` if none was).
        stationarity : float
            Its :meth:`stationarity`.
        steps : int
            Newton steps (normal equations built and solved).

        """
        shape = points.shape
        stationarity = self.stationarity(points) if stationarity is None else stationarity
        if stationarity <= tol:
            return points, stationarity, 0
        feasible = max(self.FEASIBLE, float(np.max(np.abs(self.violations(points)),
                                                   initial=0.0)))
        if kernel(KERNEL) is not None and np.all(np.isfinite(points)):
            return kernel(KERNEL).refine(self, points, tol, max_steps, stationarity, feasible)
        reached = {'stationarity': stationarity}

        def evaluate(flat):
            trial = flat.reshape(shape)
            violation = float(np.max(np.abs(self.violations(trial)), initial=0.0))
            value = self.objective(trial) if violation <= feasible else np.inf
            return (value if np.isfinite(value) else np.inf), None

        def done(flat, value, state):
            reached['stationarity'] = self.stationarity(flat.reshape(shape))
            return reached['stationarity'] <= tol

        fit = levenberg_marquardt(points.ravel(), evaluate, lambda flat, state: flat,
                                  max_iter=max_steps, tol=0.0, stall=0.0,
                                  step=lambda flat, damping: self._step(flat.reshape(shape),
                                                                        damping),
                                  done=done)
        return fit.x.reshape(shape), reached['stationarity'], fit.iterations
