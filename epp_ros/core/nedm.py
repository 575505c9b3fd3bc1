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
Nearest Euclidean distance matrix with a low embedding dimension (Qi & Yuan 2014).

Solves::

    min  1/2 ||H o (D - G)||_F^2
    s.t. diag(D) = 0,  D[i, j] = G[i, j] for (i, j) in `fixed`,
         D in K^n_- (an EDM),  rank(J D J) <= r

by the majorized penalty method (H.-D. Qi and X. Yuan, Math. Program. 147:351-389, 2014):
the rank constraint becomes the concave penalty ``c p(D)``, ``p(D) = sum_{i>r} lambda_i(-JDJ)``,
which is linearised at each iterate; ``f`` is majorised by a diagonally weighted quadratic
(``w_i = max(tau, max_j H_ij)``). Each outer step is then a convex projection, under the
weighted norm, onto the EDM cone intersected with the linear constraints. Substituting
``Y = W^1/2 D W^1/2`` turns it into a plain Frobenius projection onto the cone of matrices
negative semidefinite on ``sqrt(w)``-perp, which is solved through its dual by a semismooth
Newton method (H.-D. Qi, SIAM J. Matrix Anal. Appl. 34:67-93, 2013) with a dense generalized
Jacobian; our problems have n <= ~20 points.
"""
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from .edm import centering_matrix, classical_mds, rank_penalty, symmetric_eigh

__all__ = ['nearest_edm', 'project_constrained_edm', 'NearestEDMResult', 'ProjectionResult']


@dataclass
class ProjectionResult:
    """Solution of the convex subproblem (see :func:`project_constrained_edm`)."""

    matrix: np.ndarray          #: (n, n) the projection Y
    multipliers: np.ndarray     #: (k,) dual variables y of the linear constraints
    iterations: int             #: Newton iterations
    kkt_residual: float         #: ||A(Y) - b||, the only KKT condition not exact by construction
    converged: bool


@dataclass
class NearestEDMResult:
    """Solution of :func:`nearest_edm`."""

    edm: np.ndarray             #: (n, n) squared distances
    points: np.ndarray          #: (n, rank) classical-MDS embedding of `edm`, centred
    objective: float            #: 1/2 ||H o (D - G)||^2
    rank_error: float           #: p(D) / trace(-JDJ): 0 when D embeds in `rank` dimensions
    iterations: int             #: outer (penalty/majorization) iterations
    inner_iterations: int       #: Newton iterations summed over all subproblems
    kkt_residual: float         #: of the last subproblem, in the units of G
    penalty_parameter: float
    converged: bool


def _constraint_operator(n, pairs):
    """
    Rows and columns of the linear constraints ``A(Y) = Y[rows, cols]``.

    The diagonal comes first, then the given off-diagonal ``pairs`` (k, 2) with i < j.
    ``<A_s, Y> = Y[i, j]`` with ``A_s = (e_i e_j^T + e_j e_i^T) / 2``.
    """
    rows = np.concatenate([np.arange(n), pairs[:, 0]]).astype(int)
    cols = np.concatenate([np.arange(n), pairs[:, 1]]).astype(int)
    return rows, cols


class _Projector:
    """
    Projection onto ``K_-(q)`` with prescribed entries, for one constraint structure.

    Holds what does not change between the projections of one ``nearest_edm`` call.
    """

    def __init__(self, q, rows, cols):
        self.n = q.size
        self.rows, self.cols = rows, cols
        self.centering = centering_matrix(q)
        self.gram = np.where(rows == cols, 1.0, 0.5)     # <A_s, A_t>: diagonal
        self.flat = rows * self.n + cols
        self.flat_transposed = cols * self.n + rows
        self.diagonal = np.arange(rows.size) * (rows.size + 1)   # of the (k, k) Hessian
        self.upper_a, self.upper_b = np.triu_indices(self.n)
        # -1/4 of each (a, b) term of the Hessian, counted twice off the diagonal.
        self.pair_factor = np.where(self.upper_a == self.upper_b, -0.25, -0.5)

    def adjoint(self, y):
        """``A*(y) = sum_s y_s A_s`` as a symmetric (n, n) matrix (pairs are unique)."""
        out = np.zeros(self.n * self.n)
        out[self.flat] = 0.5 * y
        out[self.flat_transposed] += 0.5 * y
        return out.reshape(self.n, self.n)

    def evaluate(self, target, values, y):
        """Dual value, gradient, primal projection and the eigensystem behind it."""
        z = target + self.adjoint(y)
        centred = self.centering @ z @ self.centering
        eigenvalues, eigenvectors = symmetric_eigh(centred)
        projection = z - (eigenvectors * np.maximum(eigenvalues, 0.0)) @ eigenvectors.T
        value = 0.5 * np.sum(projection * projection) - values @ y
        gradient = projection[self.rows, self.cols] - values
        return value, gradient, projection, eigenvalues, eigenvectors

    def newton_matrix(self, eigenvalues, eigenvectors, regularisation):
        """
        Generalized Hessian ``A V A*`` of the dual (+ regularisation), (k, k).

        Sums over the eigenvector pairs (a, b) run over a <= b only: both factors are
        symmetric in (a, b).
        """
        first, second = eigenvalues[self.upper_a], eigenvalues[self.upper_b]
        diff = first - second
        close = np.abs(diff) <= 1e-14
        # Clarke Jacobian of Pi_{S+}: first divided differences of max(., 0).
        omega = np.divide(np.maximum(first, 0.0) - np.maximum(second, 0.0), diff,
                          out=((first > 0) & (second > 0)).astype(float), where=~close)
        basis = self.centering @ eigenvectors
        left, right = basis[self.rows], basis[self.cols]
        blocks = (left[:, self.upper_a] * right[:, self.upper_b]
                  + right[:, self.upper_a] * left[:, self.upper_b])
        hessian = (blocks * (omega * self.pair_factor)) @ blocks.T
        hessian.flat[self.diagonal] += self.gram + regularisation
        return hessian

    def newton_step(self, eigenvalues, eigenvectors, gradient, regularisation):
        """Solve ``(A V A* + reg I) step = -gradient``: positive definite, so by Cholesky."""
        hessian = self.newton_matrix(eigenvalues, eigenvectors, regularisation)
        _, step, info = lapack.dposv(hessian, -gradient)
        return step if info == 0 else np.linalg.lstsq(hessian, -gradient, rcond=None)[0]

    def __call__(self, target, values, multipliers=None, tol=1e-10, max_iter=50):
        y = np.zeros(self.rows.size) if multipliers is None else multipliers.copy()
        tol = tol * max(1.0, float(np.linalg.norm(target)))
        value, gradient, projection, eigenvalues, eigenvectors = self.evaluate(target, values, y)
        iterations = 0
        while np.linalg.norm(gradient) > tol and iterations < max_iter:
            iterations += 1
            regularisation = min(1e-2, float(np.linalg.norm(gradient))) + 1e-12
            step = self.newton_step(eigenvalues, eigenvectors, gradient, regularisation)
            slope = gradient @ step
            if slope >= 0:                            # not a descent direction: fall back
                step, slope = -gradient, -gradient @ gradient
            size = 1.0
            slack = 1e-13 * max(1.0, abs(value))     # round-off in theta near the solution
            for _ in range(30):
                trial = self.evaluate(target, values, y + size * step)
                if trial[0] <= value + 1e-4 * size * slope + slack:
                    break
                size *= 0.5
            y = y + size * step
            value, gradient, projection, eigenvalues, eigenvectors = trial
        residual = float(np.linalg.norm(gradient))
        return ProjectionResult(projection, y, iterations, residual, residual <= tol)


def project_constrained_edm(target, q, rows, cols, values, multipliers=None, tol=1e-10,
                            max_iter=50):
    """
    Nearest matrix to ``target`` in ``K_-(q)`` with prescribed entries.

    Solves ``min 1/2 ||Y - T||^2  s.t.  Y[rows, cols] = values,  J_q Y J_q NSD`` through its
    dual ``min_y theta(y) = 1/2 ||Pi_K(T + A*y)||^2 - <values, y>``, a smooth convex function
    with a strongly semismooth gradient ``A(Pi_K(T + A*y)) - values``. Newton steps use an
    element of the Clarke generalized Jacobian built from one eigendecomposition, with a
    small proximal regularisation and an Armijo line search (globally convergent, locally
    quadratic).

    Parameters
    ----------
    target : ndarray, shape (n, n), symmetric
        T, the matrix to approximate.
    q : ndarray, shape (n,), positive
        Centering direction of the cone (ones for the EDM cone itself).
    rows, cols : ndarray of int, shape (k,)
        Entries held fixed, each pair once; must include the diagonal for an EDM.
    values : ndarray, shape (k,)
        Their values.
    multipliers : ndarray, shape (k,), optional
        Warm start for the dual variables.
    tol : float
        Stop when ``||A(Y) - values|| <= tol * max(1, ||T||)`` (round-off grows with T).
    max_iter : int
        Newton steps at most.

    Returns
    -------
    ProjectionResult

    """
    projector = _Projector(np.asarray(q, dtype=float), np.asarray(rows), np.asarray(cols))
    return projector(np.asarray(target, dtype=float), np.asarray(values, dtype=float),
                     multipliers, tol, max_iter)


def nearest_edm(target, weights=None, *, rank=3, fixed=None, initial=None, tol=1e-7,
                rank_tol=1e-8, max_iter=300, tau=0.1, penalty_parameter=None,
                inner_tol=1e-9):
    """
    Nearest EDM of embedding dimension ``rank`` to a partly known squared-distance matrix.

    Parameters
    ----------
    target : ndarray, shape (n, n), symmetric
        G, squared distances. Entries with zero weight that are not fixed are ignored
        (they may be NaN).
    weights : ndarray, shape (n, n), symmetric, >= 0, optional
        H, the weight of each entry of G; ones by default. Use 0 for unknown entries.
    rank : int
        Embedding dimension r (3 for space, 2 for a plane).
    fixed : ndarray of bool, shape (n, n), symmetric, optional
        Entries of D held equal to G (e.g. known anchor distances or squared arm lengths).
    initial : ndarray, shape (n, n), optional
        Starting EDM D^0 of rank <= r (a warm start), from which the penalty iterations
        start with c = 1. Without one they start from the convex relaxation (c = 0).
    tol : float
        Stop when the relative change of ``sqrt(f + c p)`` falls below ``tol`` ...
    rank_tol : float
        ... and the relative rank error ``p(D) / trace(-JDJ)`` is below ``rank_tol``.
    max_iter : int
        Outer iterations at most.
    tau : float
        Floor of the majorization weights ``w_i = max(tau, max_j H_ij)``.
    penalty_parameter : float, optional
        Initial c; by default from the rank error of the convex solution, clamped to
        [1, 1e3] in the scaled problem (1 from a warm start); multiplied by 4 while the
        rank error is large and by 1.2 while it is above ``rank_tol``.
    inner_tol : float
        Relative tolerance of the convex subproblem: fixed entries are held to about this
        fraction of the largest squared distance (1e-9: under a micrometre on a 40 m boom).

    Returns
    -------
    NearestEDMResult

    Notes
    -----
    The problem is solved in units where the largest known squared distance is 1; results
    are returned in the units of ``target``.

    """
    target = np.asarray(target, dtype=float)
    n = target.shape[0]
    if target.shape != (n, n):
        raise ValueError(f'target must be square, got shape {target.shape}')
    weights = np.ones((n, n)) if weights is None else np.asarray(weights, dtype=float)
    fixed = np.zeros((n, n), bool) if fixed is None else np.asarray(fixed, dtype=bool)
    if weights.shape != (n, n) or fixed.shape != (n, n):
        raise ValueError('weights and fixed must have the shape of target')
    if np.any(weights < 0) or not np.all(np.isfinite(weights)):
        raise ValueError('weights must be finite and >= 0')
    weights = weights.copy()
    np.fill_diagonal(weights, 0.0)
    fixed = fixed | fixed.T
    np.fill_diagonal(fixed, False)
    known = (weights > 0) | fixed
    if not np.all(np.isfinite(target[known])):
        raise ValueError('target must be finite where weights > 0 or fixed')
    if not 1 <= rank < n:
        raise ValueError(f'rank must be in [1, n-1], got {rank}')

    scale = float(np.max(np.abs(target[known]))) if known.any() else 1.0
    scale = scale if scale > 0 else 1.0
    goal = np.where(known, target, 0.0) / scale
    goal = 0.5 * (goal + goal.T)
    sq_weights = weights ** 2

    upper = np.argwhere(np.triu(fixed, 1))
    rows, cols = _constraint_operator(n, upper)
    fixed_values = goal[rows, cols]
    majorizer = np.maximum(tau, weights.max(axis=1))      # w
    q = np.sqrt(majorizer)
    w_outer = np.outer(majorizer, majorizer)
    q_outer = np.outer(q, q)
    constraint_values = fixed_values * q_outer[rows, cols]

    def objective(edm):
        return 0.5 * np.sum(sq_weights * (edm - goal) ** 2)

    projector = _Projector(q, rows, cols)
    centering = centering_matrix(np.ones(n))
    state = {'multipliers': None, 'inner_iterations': 0, 'kkt_residual': 0.0}

    def point(edm):
        """Return an iterate with its rank penalty, trace and leading eigenvectors (one eigh)."""
        return edm, rank_penalty(edm, rank)

    def mm_step(current, c):
        """Minimiser of the majorant of f + c p at ``current`` over the constraint set."""
        edm, (_, _, leading) = current
        basis = centering @ leading if c > 0 else np.zeros((n, 0))
        complement = centering - basis @ basis.T          # J (I - U) J
        shifted = edm - (sq_weights * (edm - goal) - c * complement) / w_outer
        projected = projector(shifted * q_outer, constraint_values, state['multipliers'],
                              tol=inner_tol)
        state['multipliers'] = projected.multipliers
        state['inner_iterations'] += projected.iterations
        return point(projected.matrix / q_outer), projected.kkt_residual

    def squarem_step(current, c):
        """
        One SQUAREM cycle (Varadhan & Roland 2008) on the MM map, never worse than 2 steps.

        The MM map converges linearly and slowly along weakly determined directions (zero
        or unequal weights); squared extrapolation removes most of that tail.
        """
        first, _ = mm_step(current, c)
        second, residual = mm_step(first, c)
        step, curvature = first[0] - current[0], second[0] - 2.0 * first[0] + current[0]
        norm_curvature = np.linalg.norm(curvature)
        if norm_curvature > 1e-15:
            alpha = min(-np.linalg.norm(step) / norm_curvature, -1.0)
            candidate, candidate_residual = mm_step(
                point(current[0] - 2.0 * alpha * step + alpha ** 2 * curvature), c)
            if merit(candidate, c) <= merit(second, c):
                second, residual = candidate, candidate_residual
        state['kkt_residual'] = residual          # of the iterate kept
        return second, 3 if norm_curvature > 1e-15 else 2

    def merit(current, c):
        return objective(current[0]) + c * current[1][0]

    if initial is None:
        # Start from the convex relaxation (c = 0), with c set by its rank error.
        current, _ = squarem_step(point(np.where(known, goal, 0.0)), 0.0)
        c = float(np.clip(current[1][0], 1.0, 1e3))
    else:
        # A warm start is already of rank r: penalise from it directly.
        current = point(np.asarray(initial, dtype=float) / scale)
        c = 1.0
    if penalty_parameter is not None:
        c = float(penalty_parameter) / scale

    def relative_rank_error(current):
        penalty, trace, _ = current[1]
        return penalty / trace if trace > 0 else 0.0

    rank_error = relative_rank_error(current)
    converged = initial is None and rank_error <= rank_tol
    iterations = 0
    while not converged and iterations < max_iter:
        previous = np.sqrt(merit(current, c))
        current, steps = squarem_step(current, c)
        iterations += steps
        rank_error = relative_rank_error(current)
        relative_change = abs(previous - np.sqrt(merit(current, c))) / max(1.0, previous)
        if rank_error <= rank_tol and relative_change <= tol:
            converged = True
        elif rank_error > rank_tol:
            c = min(c * (4.0 if rank_error > 0.1 * rank else 1.2), 1e12)

    edm = current[0]
    edm = 0.5 * (edm + edm.T) * scale
    np.fill_diagonal(edm, 0.0)
    return NearestEDMResult(
        edm=edm, points=classical_mds(edm, rank), objective=objective(edm / scale) * scale ** 2,
        rank_error=float(rank_error), iterations=iterations,
        inner_iterations=state['inner_iterations'], kkt_residual=state['kkt_residual'] * scale,
        penalty_parameter=c * scale,
        converged=bool(converged))
