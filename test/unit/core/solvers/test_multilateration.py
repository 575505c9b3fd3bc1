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

from epp_ros.core.solvers.multilateration import intersect_spheres, srls
import numpy as np
import pytest
from scipy.optimize import minimize


def squared_range_cost(anchors, ranges):
    return lambda x: np.sum((np.sum((anchors - x) ** 2, axis=1) - ranges ** 2) ** 2)


def test_srls_exact_ranges():
    rng = np.random.default_rng(0)
    anchors = rng.uniform(-10, 10, (5, 3))
    point = rng.uniform(-10, 10, 3)
    np.testing.assert_allclose(srls(anchors, np.linalg.norm(anchors - point, axis=1)), point,
                               atol=1e-9)


@pytest.mark.parametrize('seed', range(6))
def test_srls_matches_brute_force_global_minimum(seed):
    rng = np.random.default_rng(seed)
    dim = 2 if seed % 2 else 3
    anchors = rng.uniform(-10, 10, (dim + 2, dim))
    point = rng.uniform(-10, 10, dim)
    ranges = np.abs(np.linalg.norm(anchors - point, axis=1) + rng.normal(0, 2.0, dim + 2))
    cost = squared_range_cost(anchors, ranges)
    starts = rng.uniform(-30, 30, (40, dim))
    best = min((minimize(cost, s, method='BFGS', options={'gtol': 1e-10}).x for s in starts),
               key=cost)
    assert cost(srls(anchors, ranges)) <= cost(best) * (1 + 1e-9) + 1e-9


def test_srls_rejects_degenerate_anchors():
    coplanar = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    assert srls(coplanar, np.ones(4)) is None
    assert srls(coplanar[:3], np.ones(3)) is None


def test_sphere_intersection_gives_both_mirror_points_upper_first():
    centres = np.array([[0.0, 0, 0], [6, 0, 0], [0, 5, 1]])
    point = np.array([2.0, 1.5, 4.0])
    upper, lower = intersect_spheres(centres, np.linalg.norm(centres - point, axis=1))
    np.testing.assert_allclose(upper, point, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(centres - lower, axis=1),
                               np.linalg.norm(centres - point, axis=1), atol=1e-9)
    assert upper[2] > lower[2]
    assert intersect_spheres(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.ones(3)) is None
