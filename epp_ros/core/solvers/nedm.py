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

Once an iterate is of rank r (a warm start from a posture already is), Newton's method in
the points finishes (:mod:`~epp_ros.core.solvers.point_newton`): the MM map converges
linearly there, one projection per step, Newton's in a few steps. The stopping rule is the
same; when Newton's method does not meet it the penalty iterations go on.

:func:`nearest_edm` checks its input and drives the penalty iterations; ``_PenaltySolver``
holds one problem's fixed data and takes its MM steps and SQUAREM cycles; the iterates are
``_Iterate`` values, and the multipliers carried between subproblems a ``_DualState``.
"""
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import NamedTuple, Optional

from epp_ros.core.solvers.edm import (centering_matrix, classical_mds, gram_spectrum,
                                      rank_penalty, squared_distances, symmetric_eigh)
from epp_ros.core.solvers.point_newton import PointProblem
import numpy as np
from scipy.linalg import lapack

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
    newton_steps: int           #: Newton steps in the points that finished them
    inner_iterations: int       #: Newton iterations summed over all subproblems
    kkt_residual: float         #: of the last subproblem, in the units of G
    penalty_parameter: float    #: c at the end, in the units of G
    stationarity: float         #: KKT residual of `points`, relative (see nearest_edm)
    converged: bool             #: ``status > 0``
    status: int                 #: 1 converged, 0 max_iter reached
    message: str                #: ``status`` in words


def _constraint_operator(n, pairs):
    """
    Rows and columns of the linear constraints ``A(Y) = Y[rows, cols]``.

    The diagonal comes first, then the given off-diagonal ``pairs`` (k, 2) with i < j.
    ``<A_s, Y> = Y[i, j]`` with ``A_s = (e_i e_j^T + e_j e_i^T) / 2``.
    """
    rows = np.concatenate([np.arange(n), pairs[:, 0]]).astype(int)
    cols = np.concatenate([np.arange(n), pairs[:, 1]]).astype(int)
    return rows, cols


@lru_cache(maxsize=16)
def _upper_pairs(n):
    """
    Return the (a, b) pairs, a <= b < n, and -1/4 of each one's Hessian term (read-only).

    Counted twice off the diagonal. Kept: ``numpy.triu_indices`` builds a mask and
    gathers from it (some 20 µs a call here), and every frame asks for the same n.
    """
    upper_a, upper_b = np.triu_indices(n)
    factor = np.where(upper_a == upper_b, -0.25, -0.5)
    for array in (upper_a, upper_b, factor):
        array.setflags(write=False)
    return upper_a, upper_b, factor


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
        self.upper_a, self.upper_b, self.pair_factor = _upper_pairs(self.n)

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


#: ``NearestEDMResult.status``: of rank r and stationary to ``tol``.
_CONVERGED = 1
#: ``NearestEDMResult.status``: ``max_iter`` reached before that.
_MAX_ITER_REACHED = 0
_MESSAGES = {
    _CONVERGED: 'converged: rank error {rank_error:.2g} <= rank_tol and stationarity '
                '{stationarity:.2g} <= tol',
    _MAX_ITER_REACHED: 'not converged: max_iter reached with rank error {rank_error:.2g} '
                       '(rank_tol {rank_tol:.2g}) and stationarity {stationarity:.2g} (tol '
                       '{tol:.2g}): progress too slow to reach a stationary point',
}

# Initial c without a warm start: the convex solution's p(D), scaled units, clamped here.
_INITIAL_PENALTY_RANGE = (1.0, 1e3)
# Growth of c per outer step while the rank error is above rank_tol (PenCorr's alpha_max and
# alpha_min): fast far from rank r, gently near it so that c does not outrun the iterates
# and lock them into the rank-r configuration closest to where they happen to be.
_FAST_GROWTH = 4.0
_SLOW_GROWTH = 1.2
_MAX_PENALTY = 1e12                 # scaled units; beyond it c J(I-U)J swamps f in round-off
# The rank error counts as large above this times ``rank``: more than 10 % of the points'
# spread per embedding dimension lies beyond the r leading directions. A heuristic taken
# from PenCorr (Gao & Sun 2010), whose test is rankErr / max(1, r) > 0.1 with an absolute
# rankErr (eigenvalues of a correlation matrix); here it is the fraction p(D) / trace(-JDJ)
# in [0, 1], so nothing is derived from it, and for rank >= 10 it never holds.
_LARGE_RANK_ERROR_PER_DIMENSION = 0.1
# Below this ||second - 2 first + start|| the MM map has stopped moving: no extrapolation.
_FLAT_CURVATURE = 1e-15
# Attempts at finishing by Newton's method per call: one usually converges; a second is
# given after more cycles when the first started outside the Newton model's reach.
_NEWTON_ATTEMPTS = 2


class _Iterate(NamedTuple):
    """An EDM of the penalty iterations with what one eigendecomposition tells of it."""

    edm: np.ndarray             #: (n, n) squared distances, scaled units
    penalty: float              #: p(D) = sum_{i>r} lambda_i(-JDJ), scaled units
    trace: float                #: sum of the positive eigenvalues of -JDJ, scaled units
    leading: np.ndarray         #: (n, r) eigenvectors of the r largest: U = P1 P1^T
    points: np.ndarray          #: (n, r) its classical-MDS embedding

    @classmethod
    def at(cls, edm, rank):
        """Return ``edm`` with its rank penalty, trace, leading eigenvectors and points."""
        spectrum = gram_spectrum(edm)
        return cls(edm, *rank_penalty(edm, rank, spectrum), classical_mds(edm, rank, spectrum))

    @property
    def rank_error(self):
        """Return ``p(D) / trace(-JDJ)``: the fraction of the spread beyond r dimensions."""
        return self.penalty / self.trace if self.trace > 0 else 0.0


class _DualState(NamedTuple):
    """What one convex subproblem passes to the next, and the counts reported at the end."""

    multipliers: Optional[np.ndarray]   #: (k,) of the last projection: the next warm start
    inner_iterations: int               #: Newton iterations, summed over all projections
    kkt_residual: float                 #: of the projection that gave the iterate kept


class _Outcome(NamedTuple):
    """Where the iterations of one ``nearest_edm`` call stopped, scaled units."""

    iterate: _Iterate
    duals: _DualState
    penalty_parameter: float            #: c
    iterations: int                     #: MM steps of the penalty iterations
    newton_steps: int                   #: Newton steps in the points
    stationarity: float                 #: of ``iterate``'s points (inf when not of rank r)
    status: int                         #: one of _MESSAGES


class _PenaltySolver:
    """
    The fixed data of one ``nearest_edm`` problem, in scaled units, and its MM steps.

    Parameters
    ----------
    goal : ndarray, shape (n, n)
        G over the scale, symmetric, zero where not known.
    weights : ndarray, shape (n, n)
        H, zero diagonal.
    fixed : ndarray of bool, shape (n, n)
        Symmetric, false diagonal.
    rank, tau, inner_tol
        As in :func:`nearest_edm`.

    """

    #: Newton steps per attempt at finishing in the points; a step converges the
    #: stationarity by one to several decades.
    NEWTON_STEPS = 8

    def __init__(self, goal, weights, fixed, rank, tau, inner_tol):
        self.goal, self.rank, self.inner_tol = goal, rank, inner_tol
        self.weights, self.tau = weights, tau
        self.sq_weights = weights ** 2
        self.fixed_pairs = np.argwhere(np.triu(fixed, 1))
        self.points = PointProblem(goal, self.sq_weights, self.fixed_pairs)

    @cached_property
    def _majorant(self):
        """
        Return the MM steps' fixed data: (w w^T, q q^T, the fixed entries of Y, projector, J).

        Built at the first step: from a warm start Newton's method usually finishes alone.
        """
        n = self.goal.shape[0]
        rows, cols = _constraint_operator(n, self.fixed_pairs)
        majorizer = np.maximum(self.tau, self.weights.max(axis=1))      # w_i w_j >= H_ij^2
        q = np.sqrt(majorizer)
        q_outer = np.outer(q, q)
        # Fixed entries of D, as entries of Y = W^1/2 D W^1/2.
        constraint_values = self.goal[rows, cols] * q_outer[rows, cols]
        return (np.outer(majorizer, majorizer), q_outer, constraint_values,
                _Projector(q, rows, cols), centering_matrix(np.ones(n)))

    def iterate(self, edm):
        """Return ``edm`` (n, n) as an :class:`_Iterate` of this problem's rank."""
        return _Iterate.at(edm, self.rank)

    def objective(self, edm):
        """Return ``f(D) = 1/2 ||H o (D - G)||^2``, scaled units."""
        return 0.5 * np.sum(self.sq_weights * (edm - self.goal) ** 2)

    def stationarity(self, iterate):
        """
        Return the relative KKT residual of the rank-r problem at ``iterate``'s points.

        See :meth:`PointProblem.stationarity`. It measures the problem itself, not the
        penalty iterations (whose map crawls once c is large and reports no motion far
        from a minimum).
        """
        return self.points.stationarity(iterate.points)

    def newton(self, iterate, tol, stationarity):
        """
        Newton's method in the points from ``iterate`` (of rank r), until stationary to ``tol``.

        ``stationarity`` is the iterate's. Returns the iterate reached (never of larger
        ``f``: only descent steps are kept), its stationarity and the Newton steps taken.
        """
        points, stationarity, steps = self.points.refine(
            iterate.points, tol, self.NEWTON_STEPS, stationarity)
        return self.iterate(squared_distances(points)), stationarity, steps

    def merit(self, iterate, c):
        """Return ``f + c p`` at ``iterate``: what the MM steps decrease."""
        return self.objective(iterate.edm) + c * iterate.penalty

    def mm_step(self, iterate, c, duals):
        """
        Minimise the majorant of ``f + c p`` at ``iterate`` over the constraint set.

        ``p`` is concave, so its linearisation ``<D, -J (I - U) J>`` lies above it, and the
        diagonal weights ``w`` put a quadratic above ``f``: the minimiser is one weighted
        projection, warm-started from the last multipliers. Returns the new iterate and
        ``duals`` with this projection's multipliers, Newton iterations and residual.
        """
        w_outer, q_outer, constraint_values, projector, centering = self._majorant
        edm = iterate.edm
        basis = centering @ iterate.leading if c > 0 else np.zeros((edm.shape[0], 0))
        complement = centering - basis @ basis.T          # J (I - U) J
        shifted = edm - (self.sq_weights * (edm - self.goal) - c * complement) / w_outer
        projected = projector(shifted * q_outer, constraint_values, duals.multipliers,
                              tol=self.inner_tol)
        duals = _DualState(projected.multipliers, duals.inner_iterations + projected.iterations,
                           projected.kkt_residual)
        return self.iterate(projected.matrix / q_outer), duals

    def squarem_cycle(self, iterate, c, duals):
        """
        One SQUAREM cycle (Varadhan & Roland 2008) on the MM map, never worse than 2 steps.

        The MM map converges linearly and slowly along weakly determined directions (zero
        or unequal weights); squared extrapolation removes most of that tail. Returns the
        iterate kept, ``duals`` (the residual of that iterate's projection) and the MM
        steps taken, 2 or 3.
        """
        first, duals = self.mm_step(iterate, c, duals)
        second, duals = self.mm_step(first, c, duals)
        step, curvature = first.edm - iterate.edm, second.edm - 2.0 * first.edm + iterate.edm
        norm_curvature = np.linalg.norm(curvature)
        if not norm_curvature > _FLAT_CURVATURE:          # MM has stopped (or NaN)
            return second, duals, 2
        alpha = min(-np.linalg.norm(step) / norm_curvature, -1.0)     # -1 gives `second`
        extrapolated = iterate.edm - 2.0 * alpha * step + alpha ** 2 * curvature
        residual = duals.kkt_residual
        candidate, duals = self.mm_step(self.iterate(extrapolated), c, duals)
        if self.merit(candidate, c) <= self.merit(second, c):
            return candidate, duals, 3
        # The multipliers stay the last projection's (the candidate's): only a warm start.
        return second, _DualState(duals.multipliers, duals.inner_iterations, residual), 3


def _checked_weights(weights, fixed, n):
    """Return ``weights`` and ``fixed`` as (n, n) float and bool arrays, defaults filled in."""
    weights = np.ones((n, n)) if weights is None else np.asarray(weights, dtype=float)
    fixed = np.zeros((n, n), bool) if fixed is None else np.asarray(fixed, dtype=bool)
    if weights.shape != (n, n) or fixed.shape != (n, n):
        raise ValueError('weights and fixed must have the shape of target')
    if np.any(weights < 0) or not np.all(np.isfinite(weights)):
        raise ValueError('weights must be finite and >= 0')
    return weights, fixed


def _checked_input(target, weights, fixed, rank):
    """
    Validate the arguments of :func:`nearest_edm`, raising ValueError.

    Returns target (n, n), weights with a zero diagonal, fixed made symmetric with a false
    diagonal, and the known entries (weighted or fixed), as new arrays.
    """
    target = np.asarray(target, dtype=float)
    n = target.shape[0]
    if target.shape != (n, n):
        raise ValueError(f'target must be square, got shape {target.shape}')
    weights, fixed = _checked_weights(weights, fixed, n)
    weights = weights.copy()
    np.fill_diagonal(weights, 0.0)
    fixed = fixed | fixed.T
    np.fill_diagonal(fixed, False)
    known = (weights > 0) | fixed
    if not np.all(np.isfinite(target[known])):
        raise ValueError('target must be finite where weights > 0 or fixed')
    if not 1 <= rank < n:
        raise ValueError(f'rank must be in [1, n-1], got {rank}')
    return target, weights, fixed, known


def _scaled_goal(target, known):
    """
    Return ``G / scale`` (symmetric, zero where not known) and ``scale``.

    ``scale`` is the largest known |G| (1 if there is none): the tolerances and the range of
    the initial c are then independent of the units of ``target``.
    """
    scale = float(np.max(np.abs(target[known]))) if known.any() else 1.0
    scale = scale if scale > 0 else 1.0
    goal = np.where(known, target, 0.0) / scale
    return 0.5 * (goal + goal.T), scale


def _start(solver, known, initial, scale, penalty_parameter):
    """
    First iterate, dual state and penalty parameter c of the penalty iterations.

    Without a warm start: one SQUAREM cycle on the convex relaxation (c = 0) from the known
    entries, and c of the size of its rank penalty (a heuristic). A warm start is already
    of rank r: the penalty applies from it, with c = 1.
    """
    duals = _DualState(None, 0, 0.0)
    if initial is None:
        relaxed = solver.iterate(np.where(known, solver.goal, 0.0))
        iterate, duals, _ = solver.squarem_cycle(relaxed, 0.0, duals)
        c = float(np.clip(iterate.penalty, *_INITIAL_PENALTY_RANGE))
    else:
        iterate = solver.iterate(np.asarray(initial, dtype=float) / scale)
        c = 1.0
    if penalty_parameter is not None:
        c = float(penalty_parameter) / scale
    return iterate, duals, c


def _next_penalty(c, rank_error, rank, rank_tol):
    """Return c for the next step: grown while the rank error is above ``rank_tol``."""
    if rank_error > rank_tol:
        large = rank_error > _LARGE_RANK_ERROR_PER_DIMENSION * rank
        return min(c * (_FAST_GROWTH if large else _SLOW_GROWTH), _MAX_PENALTY)
    return c


def _stationarity(solver, iterate, rank_tol):
    """Return the KKT residual of ``iterate``, or inf while its rank error is above rank_tol."""
    return solver.stationarity(iterate) if iterate.rank_error <= rank_tol else np.inf


def _penalty_iterations(solver, iterate, duals, c, tol, rank_tol, max_iter):
    """
    SQUAREM cycles on ``f + c p``, c following the schedule, until the stopping rule holds.

    The rule: of rank r (rank error <= ``rank_tol``) and stationary (KKT residual <= ``tol``,
    see :meth:`_PenaltySolver.stationarity`). Slow progress is not convergence: once c is
    large the MM map crawls along the rank-r set, changing ``f + c p`` by little per cycle
    far from a minimum. Whenever an iterate is of rank r (a warm start, or after a cycle),
    Newton's method in the points tries to finish (at most ``_NEWTON_ATTEMPTS`` times): the
    start or the cycles choose the basin, the Newton steps converge in it. Returns an
    :class:`_Outcome`.
    """
    iterations = newton_steps = attempts = 0
    while True:
        stationarity = _stationarity(solver, iterate, rank_tol)
        if tol < stationarity < np.inf and attempts < _NEWTON_ATTEMPTS:
            attempts += 1
            iterate, stationarity, steps = solver.newton(iterate, tol, stationarity)
            newton_steps += steps
        if stationarity <= tol:
            return _Outcome(iterate, duals, c, iterations, newton_steps, stationarity,
                            _CONVERGED)
        if iterations >= max_iter:
            return _Outcome(iterate, duals, c, iterations, newton_steps, stationarity,
                            _MAX_ITER_REACHED)
        iterate, duals, steps = solver.squarem_cycle(iterate, c, duals)
        iterations += steps
        c = _next_penalty(c, iterate.rank_error, solver.rank, rank_tol)


def _result(solver, outcome, scale, tolerances):
    """Return ``outcome`` as a :class:`NearestEDMResult` in the units of the target."""
    edm = outcome.iterate.edm
    edm = 0.5 * (edm + edm.T) * scale
    np.fill_diagonal(edm, 0.0)
    return NearestEDMResult(
        edm=edm, points=classical_mds(edm, solver.rank),
        objective=solver.objective(edm / scale) * scale ** 2,
        rank_error=float(outcome.iterate.rank_error), iterations=outcome.iterations,
        newton_steps=outcome.newton_steps,
        inner_iterations=outcome.duals.inner_iterations,
        kkt_residual=outcome.duals.kkt_residual * scale,
        penalty_parameter=outcome.penalty_parameter * scale,
        stationarity=outcome.stationarity, converged=outcome.status == _CONVERGED,
        status=outcome.status, message=_MESSAGES[outcome.status].format(
            rank_error=outcome.iterate.rank_error, stationarity=outcome.stationarity,
            **tolerances))


def nearest_edm(target, weights=None, *, rank=3, fixed=None, initial=None, tol=1e-7,
                rank_tol=1e-8, max_iter=300, tau=0.1, penalty_parameter=None,
                inner_tol=1e-9):
    """
    Nearest EDM of embedding dimension ``rank`` to a partly known squared-distance matrix.

    Parameters
    ----------
    target : ndarray, shape (n, n), symmetric
        G, squared distances (m^2 for ranges in metres). Entries with zero weight that are
        not fixed are ignored (they may be NaN).
    weights : ndarray, shape (n, n), symmetric, >= 0, optional
        H, the weight of each entry of G; ones by default. Use 0 for unknown entries.
    rank : int
        Embedding dimension r (3 for space, 2 for a plane).
    fixed : ndarray of bool, shape (n, n), symmetric, optional
        Entries of D held equal to G (e.g. known anchor distances or squared arm lengths).
    initial : ndarray, shape (n, n), optional
        Starting EDM D^0 of rank <= r (a warm start), units of ``target``, from which the
        penalty iterations start with c = 1. Without one they start from the convex
        relaxation (c = 0).
    tol : float
        Converged when the relative KKT residual of the returned points (``stationarity``,
        see Notes) is at most ``tol`` ...
    rank_tol : float
        ... and the relative rank error ``p(D) / trace(-JDJ)`` is at most ``rank_tol``.
    max_iter : int
        Outer iterations (MM steps) at most; a SQUAREM cycle of 2 or 3 steps may pass it.
    tau : float
        Floor of the majorization weights ``w_i = max(tau, max_j H_ij)``.
    penalty_parameter : float, optional
        Initial c, units of ``target``. By default from the rank penalty ``p(D)`` of the
        convex solution, clamped to [1, 1e3] in the scaled problem (1 from a warm start);
        multiplied by 4 while the rank error is above ``0.1 * rank`` and by 1.2 while it is
        above ``rank_tol``, up to 1e12 (scaled).
    inner_tol : float
        Relative tolerance of the convex subproblem: fixed entries are held to about this
        fraction of the largest squared distance (1e-9: under a micrometre on a 40 m boom).

    Returns
    -------
    NearestEDMResult
        ``status`` is 1 (converged: rank error <= ``rank_tol`` and stationarity <= ``tol``)
        or 0 (``max_iter`` reached first; the message gives both measures);
        ``converged`` is ``status > 0``.

    Notes
    -----
    The problem is solved in units where the largest known squared distance is 1; results
    are returned in the units of ``target``.

    ``stationarity`` is the first-order (KKT) condition of the rank-r problem in the
    returned points ``X``: ``|grad f(X) + J_c(X)^T mu|_F / (4 max(H o H) |X|_F max|G|)``
    with the least-squares multipliers ``mu`` of the fixed distances, or the largest
    violation of a fixed squared distance over ``max|G|`` when that is larger. It does not
    depend on the penalty parameter, and slow progress does not pass for it: once c is
    large the MM map moves the iterate along the rank-r set by little per step while far
    from a minimum (on weighted problems, by a few per cent of f or more). Like any
    first-order measure it bounds the distance to a minimum only where f curves: near a
    minimum with smallest curvature ``mu``, ``f - f* <~ |grad f|^2 / (2 mu)``; along flat
    valleys (points that span fewer than ``rank`` dimensions, missing distances) a point
    stationary to ``tol`` may still be some way from the minimum. Fixed distances are held
    to about ``inner_tol``: a ``tol`` below ~10 ``inner_tol`` cannot be met.

    """
    target, weights, fixed, known = _checked_input(target, weights, fixed, rank)
    goal, scale = _scaled_goal(target, known)
    solver = _PenaltySolver(goal, weights, fixed, rank, tau, inner_tol)
    iterate, duals, c = _start(solver, known, initial, scale, penalty_parameter)
    outcome = _penalty_iterations(solver, iterate, duals, c, tol, rank_tol, max_iter)
    if (outcome.status == _CONVERGED and outcome.iterations == outcome.newton_steps == 0
            and solver.fixed_pairs.size):
        # A start stationary within tol came back as it was, its fixed distances off by up
        # to tol: they are known. Moved the least onto them, it is judged again.
        points = solver.points.onto_fixed(outcome.iterate.points)
        outcome = _penalty_iterations(solver, solver.iterate(squared_distances(points)),
                                      outcome.duals, c, tol, rank_tol, max_iter)
    return _result(solver, outcome, scale, {'tol': tol, 'rank_tol': rank_tol})
