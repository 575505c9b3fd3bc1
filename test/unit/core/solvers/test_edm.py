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

from epp_ros.core.solvers.edm import (align_to_known, centering_matrix, classical_mds,
                                      double_centre, gram_spectrum, project_edm_cone,
                                      rank_penalty, refine_stress, squared_distances,
                                      symmetric_eigh)
import numpy as np


def random_rotation(rng, dim, reflect=False):
    q, r = np.linalg.qr(rng.standard_normal((dim, dim)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    if reflect:
        q[:, 0] *= -1
    return q


def test_symmetric_eigh_and_double_centre_match_their_definitions():
    rng = np.random.default_rng(3)
    matrix = rng.standard_normal((7, 7))
    matrix = matrix + matrix.T
    eigenvalues, eigenvectors = symmetric_eigh(matrix)
    np.testing.assert_allclose(eigenvalues, np.linalg.eigvalsh(matrix), atol=1e-12)
    assert np.all(np.diff(eigenvalues) >= 0)
    np.testing.assert_allclose(eigenvectors @ np.diag(eigenvalues) @ eigenvectors.T, matrix,
                               atol=1e-12)
    np.testing.assert_allclose(eigenvectors.T @ eigenvectors, np.eye(7), atol=1e-12)
    j = centering_matrix(np.ones(7))
    np.testing.assert_allclose(double_centre(matrix), j @ matrix @ j, atol=1e-12)


def test_squared_distances_known_values():
    points = np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 1.0]])
    np.testing.assert_allclose(squared_distances(points),
                               [[0, 25, 1], [25, 0, 18], [1, 18, 0]])


def test_cone_projection_is_a_projection():
    rng = np.random.default_rng(1)
    a = rng.standard_normal((7, 7))
    a = a + a.T
    projected = project_edm_cone(a)
    j = centering_matrix(np.ones(7))
    assert np.linalg.eigvalsh(j @ projected @ j).max() <= 1e-10     # in K^n_-
    np.testing.assert_allclose(project_edm_cone(projected), projected, atol=1e-10)
    # Moreau: the residual is PSD, orthogonal to the projection, and annihilates e.
    residual = a - projected
    assert np.linalg.eigvalsh(residual).min() >= -1e-10
    np.testing.assert_allclose(residual @ np.ones(7), 0.0, atol=1e-10)
    assert abs(np.sum(residual * projected)) <= 1e-9


def test_edm_is_fixed_by_projection_and_has_no_rank_penalty():
    rng = np.random.default_rng(2)
    edm = squared_distances(rng.standard_normal((8, 3)))
    np.testing.assert_allclose(project_edm_cone(edm), edm, atol=1e-10)
    penalty, trace, leading = rank_penalty(edm, 3)
    assert penalty <= 1e-10 * trace and leading.shape == (8, 3)
    assert rank_penalty(edm, 2)[0] > 1e-3


def test_classical_mds_recovers_points_up_to_rigid_motion():
    rng = np.random.default_rng(3)
    points = rng.standard_normal((9, 3)) * 5
    embedded = classical_mds(squared_distances(points), 3)
    np.testing.assert_allclose(squared_distances(embedded), squared_distances(points),
                               atol=1e-9)


def test_one_spectrum_gives_the_rank_penalty_and_the_embedding_of_a_matrix_near_an_edm():
    rng = np.random.default_rng(5)
    edm = squared_distances(rng.standard_normal((9, 3)) * 5)
    noisy = edm + rng.normal(0.0, 0.5, edm.shape)
    noisy = 0.5 * (noisy + noisy.T)
    np.fill_diagonal(noisy, 0.0)
    eigenvalues, eigenvectors = np.linalg.eigh(-0.5 * double_centre(noisy))
    top = eigenvectors[:, -2:] * np.sqrt(eigenvalues[-2:])
    embedded = classical_mds(noisy, 2)
    # The Gram matrix of the top two: the same whatever the eigenvectors' signs.
    np.testing.assert_allclose(embedded @ embedded.T, top @ top.T, atol=1e-9)
    spectrum = gram_spectrum(noisy)
    np.testing.assert_allclose(spectrum[0], 2.0 * eigenvalues[::-1], atol=1e-9)
    assert np.array_equal(classical_mds(noisy, 2, spectrum), embedded)
    assert rank_penalty(noisy, 2, spectrum)[:2] == rank_penalty(noisy, 2)[:2]
    penalty, trace, _ = rank_penalty(noisy, 2)
    positive = np.maximum(2.0 * eigenvalues[::-1], 0.0)
    assert np.isclose(penalty, positive[2:].sum()) and np.isclose(trace, positive.sum())


def test_alignment_undoes_rotation_reflection_and_translation():
    rng = np.random.default_rng(4)
    points = rng.standard_normal((10, 3)) * 4
    for reflect in (False, True):
        moved = points @ random_rotation(rng, 3, reflect) + [1.0, -2.0, 3.0]
        aligned = align_to_known(moved, np.arange(5), points[:5])
        np.testing.assert_allclose(aligned, points, atol=1e-10)
        pinned = align_to_known(moved, np.arange(5), points[:5], pivot=2)
        np.testing.assert_allclose(pinned, points, atol=1e-10)


def test_pivot_is_matched_exactly_under_noise():
    rng = np.random.default_rng(5)
    points = rng.standard_normal((6, 3)) * 4
    noisy = points + 0.1 * rng.standard_normal(points.shape)
    aligned = align_to_known(noisy, np.arange(4), points[:4], pivot=1)
    np.testing.assert_allclose(aligned[1], points[1], atol=1e-12)
    np.testing.assert_allclose(squared_distances(aligned), squared_distances(noisy), atol=1e-9)


def test_coplanar_known_points_choose_the_upper_mirror_image():
    known = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0], [4.0, 4.0, 0.0]])
    points = np.vstack([known, [[1.0, 2.0, 7.0], [2.0, 1.0, 9.0]]])
    below = points * [1.0, 1.0, -1.0]
    rotated = below @ random_rotation(np.random.default_rng(6), 3)
    aligned = align_to_known(rotated, np.arange(4), known)
    np.testing.assert_allclose(aligned, points, atol=1e-10)


def stress(points, distances, weights):
    gaps = np.sqrt(squared_distances(points)) - distances
    return 0.5 * np.sum(weights * gaps ** 2)


def test_stress_refinement_returns_points_their_exact_distances_determine():
    rng = np.random.default_rng(3)
    anchors = rng.uniform(-10.0, 10.0, (5, 3))
    tags = rng.uniform(-10.0, 10.0, (4, 3))
    truth = np.vstack([anchors, tags])
    distances = np.sqrt(squared_distances(truth))
    weights = np.ones(distances.shape) - np.eye(9)
    weights[5:, 5:] = 0.0           # tag-tag distances unknown: anchors alone place the tags
    start = truth + np.r_[np.zeros((5, 3)), rng.normal(0.0, 0.5, (4, 3))]
    refined, evaluations = refine_stress(start, np.arange(5, 9), distances, weights)
    np.testing.assert_allclose(refined, truth, atol=1e-8)
    assert evaluations > 0
    np.testing.assert_array_equal(refined[:5], anchors)


def test_stress_refinement_lowers_the_stress_and_leaves_undetermined_points():
    rng = np.random.default_rng(4)
    points = rng.uniform(-5.0, 5.0, (6, 2))
    distances = np.sqrt(squared_distances(points)) + np.triu(rng.normal(0, 0.3, (6, 6)), 1)
    distances = np.triu(distances, 1) + np.triu(distances, 1).T
    weights = rng.uniform(0.5, 2.0, (6, 6))
    weights = np.triu(weights, 1) + np.triu(weights, 1).T
    refined, _ = refine_stress(points, [3, 4, 5], distances, weights)
    assert stress(refined, distances, weights) < stress(points, distances, weights)
    # A free point with one distance has no unique place: it is left where it was.
    lone = np.zeros((6, 6))
    lone[0, 5] = lone[5, 0] = 1.0
    unmoved, evaluations = refine_stress(points, [5], distances, lone)
    assert evaluations == 0 and np.array_equal(unmoved, points)
