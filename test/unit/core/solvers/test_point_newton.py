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
Newton's method in the points, and ``nearest_edm`` finishing with it.

Every test runs on both paths, compiled (``compiled_points``) and numpy;
``test_compiled_points`` compares the two on the same problems.
"""
from epp_ros.core.solvers import compiled, nedm
from epp_ros.core.solvers.edm import squared_distances
from epp_ros.core.solvers.point_newton import PointProblem
import numpy as np
import pytest
from scipy.optimize import least_squares


@pytest.fixture(autouse=True, params=['compiled', 'numpy'])
def path(request, monkeypatch):
    """Run the test with the points' Newton steps compiled, then in numpy."""
    monkeypatch.setattr(compiled, 'COMPILED', request.param == 'compiled')
    return request.param


def chain_problem(seed, sections=5, anchors=4, noise=0.05):
    """
    Return a boom in a plane, with noisy squared ranges to anchors, scaled to at most 1.

    The anchors are fixed among themselves, the pivot (0) among them; the arm lengths are
    fixed; every joint has a range to each anchor but the pivot.

    Returns the goal (n, n), H o H, the fixed pairs (k, 2), the true points (n, 2) and the
    squared arm lengths.
    """
    rng = np.random.default_rng(seed)
    known = np.vstack([[0.0, 0.0], rng.uniform([-3, -1], [3, 0], (anchors, 2))])
    lengths = rng.uniform(5, 9, sections)
    angles = np.cumsum(rng.uniform(-0.6, 0.6, sections)) + 0.7
    joints = np.cumsum(lengths[:, None] * np.c_[np.cos(angles), np.sin(angles)], axis=0)
    points = np.vstack([known, joints])
    n, k = points.shape[0], known.shape[0]
    goal = squared_distances(points)
    # Only the ranges to the anchors (not the pivot, 0) are noisy and weighted.
    ranges = (slice(k, n), slice(1, k))
    goal[ranges] += noise * rng.standard_normal((sections, k - 1)) * 2 * np.sqrt(goal[ranges])
    goal[:k, k:] = goal[k:, :k].T
    sq_weights = np.zeros((n, n))
    sq_weights[ranges] = rng.uniform(0.5, 2.0, (sections, k - 1))
    sq_weights[:k, k:] = sq_weights[k:, :k].T
    chain = np.r_[0, np.arange(k, n)]
    fixed = [(a, b) for a in range(k) for b in range(a + 1, k)]
    fixed += list(zip(chain[:-1], chain[1:]))
    scale = goal.max()
    return goal / scale, sq_weights, np.array(fixed), points / np.sqrt(scale)


def angle_fit(problem, points, k):
    """Fit the same problem over the joint angles (lengths and anchors exact) by scipy."""
    pivot = points[0]
    lengths = np.linalg.norm(np.diff(np.vstack([pivot, points[k:]]), axis=0), axis=1)

    def joints(angles):
        return pivot + np.cumsum(lengths[:, None] * np.c_[np.cos(angles), np.sin(angles)],
                                 axis=0)

    def residuals(angles):
        return problem.residuals(np.vstack([points[:k], joints(angles)]))
    start = np.arctan2(*np.diff(np.vstack([pivot, points[k:]]), axis=0).T[::-1])
    fitted = least_squares(residuals, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return np.vstack([points[:k], joints(fitted.x)])


@pytest.mark.parametrize('seed', range(6))
def test_newton_reaches_the_constrained_minimum_from_a_nearby_posture(seed):
    goal, sq_weights, fixed, truth = chain_problem(seed)
    problem = PointProblem(goal, sq_weights, fixed)
    # A nearby feasible posture: the true one (its ranges are noisy, so it is not the minimum).
    start_value = problem.objective(truth)
    # Stationarity has a floor of ~1e-10 here: f's round-off decides the last steps.
    points, stationarity, steps = problem.refine(truth, 1e-9, 20)
    assert stationarity <= 1e-9 and 0 < steps <= 10
    assert problem.objective(points) <= start_value
    assert np.max(np.abs(problem.violations(points))) <= 1e-12
    expected = angle_fit(problem, truth, 5)
    # Stationary to 1e-9: distances (of at most 1) agree to ~1e-9 over the curvature.
    np.testing.assert_allclose(squared_distances(points), squared_distances(expected),
                               atol=1e-7)


def test_stationarity_is_small_only_at_a_minimum_and_counts_infeasibility():
    goal, sq_weights, fixed, truth = chain_problem(7)
    problem = PointProblem(goal, sq_weights, fixed)
    points, stationarity, _ = problem.refine(truth, 1e-9, 20)
    assert stationarity == problem.stationarity(points) <= 1e-9
    # A rigid motion changes nothing; moving one joint off its arm length does.
    rotation = np.array([[0.6, -0.8], [0.8, 0.6]])
    assert problem.stationarity(points @ rotation.T + 3.0) <= 2e-9
    moved = points.copy()
    moved[-1] += 1e-3
    violation = np.max(np.abs(problem.violations(moved)))
    assert problem.stationarity(moved) >= violation > 1e-4


def bent(points, k, angle):
    """``points`` with the boom's first joint turned by ``angle`` about the pivot (0)."""
    cos, sin = np.cos(angle), np.sin(angle)
    turned = points.copy()
    turned[k:] = points[0] + (points[k:] - points[0]) @ np.array([[cos, sin], [-sin, cos]])
    return turned


@pytest.mark.parametrize('angle', [0.2, 0.6, 1.2])
def test_newton_never_increases_the_objective_and_stays_feasible(angle):
    goal, sq_weights, fixed, truth = chain_problem(9)
    problem = PointProblem(goal, sq_weights, fixed)
    points = bent(truth, 5, angle)
    values = [problem.objective(points)]
    for _ in range(15):
        points, _, _ = problem.refine(points, 0.0, 1)
        values.append(problem.objective(points))
        assert np.max(np.abs(problem.violations(points))) <= 1e-12
    assert np.all(np.diff(values) <= 1e-14 * values[0])
    assert values[-1] < values[0]


def weighted_problem(seed, n, dim, fixed_pairs):
    rng = np.random.default_rng(seed)
    edm = squared_distances(rng.standard_normal((n, dim)) * 10)
    noisy = edm + rng.normal(0.0, 1.0, (n, n))
    noisy = 0.5 * (noisy + noisy.T)
    np.fill_diagonal(noisy, 0.0)
    weights = rng.uniform(0.05, 2.0, (n, n))
    weights = np.triu(weights, 1) + np.triu(weights, 1).T
    fixed = np.zeros((n, n), bool)
    for a, b in fixed_pairs:
        fixed[a, b] = fixed[b, a] = True
    return edm, noisy, weights, fixed


@pytest.mark.parametrize('seed', range(8))
def test_nearest_edm_finishes_by_newton_at_the_penalty_methods_answer(seed, monkeypatch):
    edm, noisy, weights, fixed = weighted_problem(seed, 9, 3, [(0, 1), (1, 2), (2, 3)])
    with_newton = nearest_edm_pair = nedm.nearest_edm(noisy, weights, fixed=fixed, tol=1e-9,
                                                      max_iter=20000)
    monkeypatch.setattr(nedm, '_NEWTON_ATTEMPTS', 0)
    penalty_only = nedm.nearest_edm(noisy, weights, fixed=fixed, tol=1e-9, max_iter=20000)
    assert with_newton.converged and penalty_only.converged, penalty_only.message
    assert with_newton.newton_steps > 0 and penalty_only.newton_steps == 0
    assert with_newton.iterations < penalty_only.iterations
    # Both stationary at one minimum; the penalty answer lies off rank r by up to rank_tol.
    assert with_newton.objective == pytest.approx(penalty_only.objective, rel=1e-6)
    np.testing.assert_allclose(nearest_edm_pair.edm, penalty_only.edm, atol=1e-5 * edm.max())


def test_a_warm_start_of_the_right_rank_is_finished_without_penalty_steps():
    edm, noisy, weights, fixed = weighted_problem(20, 9, 2, [(0, 1), (3, 4)])
    warm = nedm.nearest_edm(noisy, weights, rank=2, fixed=fixed, initial=edm)
    assert warm.converged and warm.iterations == 0 and warm.newton_steps > 0
    assert warm.stationarity <= 1e-7 and warm.rank_error <= 1e-8
    held = warm.edm[fixed]
    np.testing.assert_allclose(held, noisy[fixed], atol=1e-9 * noisy.max())


def test_points_that_are_not_finite_end_the_steps_without_an_exception():
    goal, sq_weights, fixed, truth = chain_problem(4)
    problem = PointProblem(goal, sq_weights, fixed)
    broken = truth.copy()
    broken[-1] = np.nan
    points, stationarity, steps = problem.refine(broken, 1e-9, 5)
    assert not stationarity <= 1e-9 and steps <= 5 and points.shape == truth.shape
