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

from epp_ros.core.edm import centering_matrix, classical_mds, squared_distances
from epp_ros.core.nedm import (_constraint_operator, _Projector, nearest_edm,
                               project_constrained_edm)
import numpy as np
import pytest


def noisy_edm(rng, n, dim, noise):
    edm = squared_distances(rng.standard_normal((n, dim)) * 10)
    perturbation = noise * rng.standard_normal((n, n))
    noisy = edm + perturbation + perturbation.T
    np.fill_diagonal(noisy, 0.0)
    return edm, noisy


@pytest.mark.parametrize('n, dim', [(4, 2), (8, 3), (12, 3), (9, 2)])
def test_edm_of_the_right_rank_is_returned_unchanged(n, dim):
    rng = np.random.default_rng(n * 10 + dim)
    edm, _ = noisy_edm(rng, n, dim, 0.0)
    result = nearest_edm(edm, rank=dim)
    np.testing.assert_allclose(result.edm, edm, atol=1e-9 * edm.max())
    np.testing.assert_allclose(squared_distances(result.points), edm, atol=1e-8 * edm.max())
    assert result.converged and result.points.shape == (n, dim)


def test_missing_entries_of_an_edm_are_completed():
    rng = np.random.default_rng(7)
    edm, _ = noisy_edm(rng, 10, 3, 0.0)
    weights = np.ones_like(edm)
    for i, j in [(0, 5), (1, 2), (3, 9)]:
        weights[i, j] = weights[j, i] = 0.0
    target = np.where(weights > 0, edm, np.nan)
    result = nearest_edm(target, weights, rank=3, tol=1e-12, initial=edm + 1.0 - np.eye(10))
    np.testing.assert_allclose(result.edm, edm, atol=1e-6 * edm.max())


def test_noisy_input_gives_a_low_rank_edm_with_fixed_entries_held():
    rng = np.random.default_rng(8)
    _, noisy = noisy_edm(rng, 10, 3, 5.0)
    fixed = np.zeros_like(noisy, bool)
    fixed[[0, 1, 2], [1, 2, 3]] = True
    result = nearest_edm(noisy, rank=3, fixed=fixed)
    d = result.edm
    assert result.converged
    np.testing.assert_allclose(np.diag(d), 0.0)
    np.testing.assert_allclose(d[fixed], noisy[fixed], rtol=1e-9)
    np.testing.assert_allclose(d, d.T)
    gram = -0.5 * centering_matrix(np.ones(10)) @ d @ centering_matrix(np.ones(10))
    eigenvalues = np.sort(np.linalg.eigvalsh(gram))[::-1]
    assert eigenvalues[-1] >= -1e-8 * eigenvalues[0]                     # an EDM
    assert eigenvalues[3:].sum() <= 1e-7 * eigenvalues.sum()            # of rank 3
    assert result.rank_error <= 1e-8
    assert result.objective == pytest.approx(0.5 * np.sum((d - noisy) ** 2), rel=1e-9)


def test_nearest_edm_beats_truncated_classical_mds():
    rng = np.random.default_rng(9)
    _, noisy = noisy_edm(rng, 9, 3, 20.0)
    truncated = squared_distances(classical_mds(noisy, 3))
    result = nearest_edm(noisy, rank=3, tol=1e-10)
    assert result.objective < 0.5 * np.sum((truncated - noisy) ** 2)


@pytest.mark.parametrize('seed', range(4))
def test_subproblem_satisfies_kkt(seed):
    rng = np.random.default_rng(100 + seed)
    n = 9
    target = rng.standard_normal((n, n)) * 3
    target = target + target.T
    q = np.sqrt(rng.uniform(0.1, 10.0, n))
    pairs = np.array([[0, 1], [1, 2], [4, 7]])
    rows, cols = _constraint_operator(n, pairs)
    values = np.r_[np.zeros(n), 1.0, 2.0, 0.5]
    result = project_constrained_edm(target, q, rows, cols, values, tol=1e-13)
    y_mat, multipliers = result.matrix, result.multipliers
    assert result.converged and result.kkt_residual <= 1e-10
    # Primal feasibility: the fixed entries, and Y negative semidefinite on q-perp.
    np.testing.assert_allclose(y_mat[rows, cols], values, atol=1e-10)
    j = centering_matrix(q)
    assert np.linalg.eigvalsh(j @ y_mat @ j).max() <= 1e-9
    # Dual feasibility and complementarity: Z = T + A*y - Y is PSD with Z q = 0, <Z, Y> = 0.
    z = target + _Projector(q, rows, cols).adjoint(multipliers) - y_mat
    assert np.linalg.eigvalsh(z).min() >= -1e-9
    np.testing.assert_allclose(z @ q, 0.0, atol=1e-9)
    assert abs(np.sum(z * y_mat)) <= 1e-8


def test_newton_matrix_is_the_jacobian_of_the_dual_gradient():
    """Away from zero or repeated eigenvalues the generalized Hessian is the true one."""
    rng = np.random.default_rng(12)
    n = 8
    target = rng.standard_normal((n, n)) * 3
    target = target + target.T
    q = np.sqrt(rng.uniform(0.5, 2.0, n))
    rows, cols = _constraint_operator(n, np.array([[0, 1], [2, 5], [3, 4], [1, 6]]))
    projector = _Projector(q, rows, cols)
    values = rng.standard_normal(rows.size)
    y = rng.standard_normal(rows.size)
    _, gradient, _, eigenvalues, eigenvectors = projector.evaluate(target, values, y)
    assert np.min(np.abs(eigenvalues[np.abs(eigenvalues) > 1e-9])) > 1e-3
    step = 1e-6
    numeric = np.stack([(projector.evaluate(target, values, y + step * e)[1]
                         - projector.evaluate(target, values, y - step * e)[1]) / (2 * step)
                        for e in np.eye(rows.size)], axis=1)
    np.testing.assert_allclose(projector.newton_matrix(eigenvalues, eigenvectors, 0.0),
                               numeric, atol=1e-6)


def test_subproblem_newton_converges_fast():
    rng = np.random.default_rng(11)
    _, noisy = noisy_edm(rng, 10, 3, 5.0)
    rows, cols = _constraint_operator(10, np.zeros((0, 2), int))
    result = project_constrained_edm(noisy / noisy.max(), np.ones(10), rows, cols,
                                     np.zeros(10), tol=1e-14)
    assert result.converged and result.iterations <= 8


@pytest.mark.parametrize('kwargs, message', [
    ({'target': np.zeros((3, 4))}, 'square'),
    ({'weights': -np.ones((4, 4))}, 'weights'),
    ({'target': np.full((4, 4), np.nan)}, 'finite'),
    ({'rank': 4}, 'rank'),
    ({'fixed': np.zeros((3, 3), bool)}, 'shape'),
])
def test_invalid_arguments_raise(kwargs, message):
    args = {'target': squared_distances(np.eye(4)), 'rank': 2}
    args.update(kwargs)
    target = args.pop('target')
    with pytest.raises(ValueError, match=message):
        nearest_edm(target, **args)


def test_status_says_how_the_iterations_ended():
    rng = np.random.default_rng(13)
    edm, noisy = noisy_edm(rng, 8, 3, 2.0)
    exact = nearest_edm(edm, rank=3)
    assert (exact.status, exact.converged) == (1, True)
    np.testing.assert_allclose(exact.edm, edm, atol=1e-8 * edm.max())
    warm = nearest_edm(noisy, rank=3, initial=edm)
    assert (warm.status, warm.converged) == (1, True) and warm.iterations > 0
    stopped = nearest_edm(noisy, rank=3, max_iter=1)
    assert (stopped.status, stopped.converged) == (0, False)
    assert 'max_iter' in stopped.message and 'converged' in warm.message


def test_a_weighted_relaxation_already_of_rank_r_is_iterated_to_its_minimum():
    # Unequal and missing weights on points in a plane: the convex relaxation's first cycle
    # is already of rank 3 but far from its minimiser (it was returned as converged).
    rng = np.random.default_rng(14)
    n = 6
    edm = squared_distances(rng.standard_normal((n, 2)) * 10)
    noisy = edm + rng.normal(0.0, 1.0, (n, n))
    noisy = 0.5 * (noisy + noisy.T)
    np.fill_diagonal(noisy, 0.0)
    weights = rng.uniform(0.05, 2.0, (n, n)) * (rng.uniform(size=(n, n)) < 0.8)
    weights = np.triu(weights, 1) + np.triu(weights, 1).T
    result = nearest_edm(noisy, weights, rank=3)
    assert result.converged and result.rank_error < 1e-8
    again = nearest_edm(noisy, weights, rank=3, initial=result.edm, tol=1e-10)
    assert again.objective >= 0.98 * result.objective     # the old answer: 4,700 times it
