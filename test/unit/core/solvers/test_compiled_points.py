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

"""The points' compiled Newton steps against their numpy reference: the same, to rounding."""
from epp_ros.core.solvers import compiled, compiled_points, point_newton
from epp_ros.core.solvers.edm import squared_distances
from epp_ros.core.solvers.point_newton import PointProblem
import numpy as np
import pytest
from test_point_newton import chain_problem


def both_paths(monkeypatch, problem, start):
    """Return (stationarity, points, stationarity, steps) of ``start``, compiled then numpy."""
    results = []
    for path in (True, False):
        monkeypatch.setattr(compiled, 'COMPILED', path)
        results.append((problem.stationarity(start),) + problem.refine(start, 1e-10, 8))
    return results


def test_the_compiled_least_squares_is_lapacks_to_the_last_bit():
    rng = np.random.default_rng(5)
    for rows, columns in ((26, 24), (24, 26), (5, 12), (12, 1), (0, 4), (3, 0)):
        matrix = rng.standard_normal((rows, columns))
        if rows > 2 and columns > 2:
            matrix[:, 2] = matrix[:, 1]          # rank-deficient, as redundant fixed pairs
        rhs = rng.standard_normal(rows)
        solution, solved = compiled_points._least_squares(matrix, rhs, compiled_points._LAPACK)
        assert solved
        np.testing.assert_array_equal(solution, point_newton._least_squares(matrix, rhs))


@pytest.mark.parametrize('order', ['C', 'F'])
def test_lapack_never_overwrites_the_callers_matrix(order):
    """LAPACK works in place: it gets a copy, whatever the order of the caller's matrix."""
    rng = np.random.default_rng(7)
    for shape in ((6, 1), (1, 6), (1, 1), (4, 3), (3, 3)):
        matrix = np.array(rng.standard_normal(shape), order=order)
        kept = matrix.copy()
        compiled_points._least_squares(matrix, rng.standard_normal(shape[0]),
                                       compiled_points._LAPACK)
        if shape[0] == shape[1]:
            compiled_points._eigh(matrix, compiled_points._LAPACK)
            compiled_points._solve(matrix, np.ones(shape[0]), compiled_points._LAPACK)
        np.testing.assert_array_equal(matrix, kept)


def test_one_fixed_pair_steps_as_numpy_does(monkeypatch):
    """The constraints' Jacobian is then one row (in both orders at once)."""
    rng = np.random.default_rng(8)
    truth = rng.uniform(-5.0, 5.0, (6, 2))
    goal = squared_distances(truth) + rng.normal(0.0, 0.5, (6, 6))
    goal = 0.5 * (goal + goal.T)
    np.fill_diagonal(goal, 0.0)
    goal /= goal.max()
    sq_weights = np.ones((6, 6)) - np.eye(6)
    problem = PointProblem(goal, sq_weights, np.array([[0, 3]]))
    start = truth / np.sqrt(squared_distances(truth).max()) + rng.normal(0.0, 0.05, (6, 2))
    ours, reference = both_paths(monkeypatch, problem, start)
    first, points, stationarity, count = ours
    expected_first, expected, expected_stationarity, expected_count = reference
    assert first == pytest.approx(expected_first, rel=1e-9) and first > 1e-10
    assert count > 0 and abs(count - expected_count) <= 1
    assert stationarity == pytest.approx(expected_stationarity, rel=1e-3, abs=1e-9)
    assert problem.objective(points) == pytest.approx(problem.objective(expected), rel=1e-6)
    np.testing.assert_allclose(squared_distances(points), squared_distances(expected),
                               atol=1e-7)


def test_the_compiled_eigendecomposition_and_solve_are_lapacks():
    rng = np.random.default_rng(6)
    matrix = rng.standard_normal((9, 9))
    matrix = matrix + matrix.T
    values, vectors, decomposed = compiled_points._eigh(matrix, compiled_points._LAPACK)
    expected_values, expected_vectors = point_newton.symmetric_eigh(matrix)
    assert decomposed
    np.testing.assert_array_equal(values, expected_values)
    np.testing.assert_array_equal(vectors, expected_vectors)
    rhs = rng.standard_normal(9)
    solution, solved = compiled_points._solve(matrix, rhs, compiled_points._LAPACK)
    assert solved
    np.testing.assert_allclose(matrix @ solution, rhs, atol=1e-12)
    singular = np.ones((3, 3))
    assert not compiled_points._solve(singular, np.ones(3), compiled_points._LAPACK)[1]


def test_the_compiled_steps_are_the_numpy_steps(monkeypatch):
    """
    Same start, same problem: the same posture, f and stationarity, to rounding.

    The points themselves may differ by a rigid motion, which nothing holds but the ridge
    (the EDM is what ``nearest_edm`` keeps). Where the last steps sit at f's round-off, one
    path may stop a step before the other.
    """
    steps = []
    for seed in range(60):
        goal, sq_weights, fixed, truth = chain_problem(
            seed, sections=3 + seed % 4, anchors=3 + seed % 5, noise=0.02 * (1 + seed % 7))
        problem = PointProblem(goal, sq_weights, fixed)
        start = truth + 0.02 * np.random.default_rng(seed).standard_normal(truth.shape)
        ours, reference = both_paths(monkeypatch, problem, start)
        first, points, stationarity, count = ours
        expected_first, expected, expected_stationarity, expected_count = reference
        assert first == pytest.approx(expected_first, rel=1e-9)
        assert abs(count - expected_count) <= 1
        steps.append(count == expected_count)
        np.testing.assert_allclose(squared_distances(points), squared_distances(expected),
                                   atol=1e-7)
        assert problem.objective(points) == pytest.approx(problem.objective(expected),
                                                          rel=1e-6, abs=1e-16)
        if max(stationarity, expected_stationarity) > 1e-7:
            assert stationarity == pytest.approx(expected_stationarity, rel=1e-3)
    assert np.mean(steps) >= 0.9
