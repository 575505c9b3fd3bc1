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
Biswas-Ye SDP baseline (optional cvxpy).

The suite runs with -W error, so a problem that is not DPP (cvxpy warns on solve) fails
these tests.
"""
import subprocess
import sys
from types import SimpleNamespace

from epp_ros.core.solvers.sdp import SDPLocalizer
import numpy as np
import pytest
from scipy.spatial import Delaunay

N_TAGS = 5


@pytest.fixture
def cvxpy():
    # A benchmark extra, but pinned in requirements.txt: missing here is a failure.
    import cvxpy
    return cvxpy


def scene(seed, n_anchors=6):
    """Non-coplanar anchors around a 6 m x 6 m room and tags inside their convex hull."""
    rng = np.random.default_rng(seed)
    corners = np.array([[-3, -3, 0.3], [3, -3, 2.6], [3, 3, 0.4], [-3, 3, 2.5],
                        [0, -4, 1.5], [0, 4, 2.9]])[:n_anchors]
    anchors = corners + rng.uniform(-0.3, 0.3, corners.shape)
    tags = anchors.mean(axis=0) + rng.uniform(-0.6, 0.6, (N_TAGS, 3))
    assert np.all(Delaunay(anchors).find_simplex(tags) >= 0)
    return anchors, tags


def exact_ranges(anchors, tags):
    return np.linalg.norm(tags[:, None, :] - anchors[None, :, :], axis=2)


@pytest.mark.parametrize('seed', range(3))
def test_noise_free_ranges_recover_positions(cvxpy, seed):
    anchors, tags = scene(seed)
    positions, info = SDPLocalizer(anchors, N_TAGS).solve(exact_ranges(anchors, tags))
    assert positions.shape == (N_TAGS, 3)
    np.testing.assert_allclose(positions, tags, atol=1e-4)
    assert info['status'] == 'optimal'
    assert info['objective'] == pytest.approx(0.0, abs=1e-5)
    assert info['solve_time'] > 0.0


def test_four_anchors_suffice_without_noise(cvxpy):
    anchors, tags = scene(3, n_anchors=4)
    positions, _ = SDPLocalizer(anchors, N_TAGS).solve(exact_ranges(anchors, tags))
    np.testing.assert_allclose(positions, tags, atol=1e-4)


def test_missing_links_are_ignored(cvxpy):
    anchors, tags = scene(4)
    ranges = exact_ranges(anchors, tags)
    ranges[[0, 1, 1, 3, 4], [2, 0, 5, 4, 1]] = np.nan      # every tag keeps >= 4 anchors
    positions, info = SDPLocalizer(anchors, N_TAGS).solve(ranges)
    np.testing.assert_allclose(positions, tags, atol=1e-4)
    assert info['objective'] == pytest.approx(0.0, abs=1e-5)


def test_missing_link_value_does_not_matter(cvxpy):
    """A NaN link gives the same estimate as any wrong value would if it were ignored."""
    anchors, tags = scene(5)
    rng = np.random.default_rng(5)
    ranges = exact_ranges(anchors, tags) + rng.normal(0.0, 0.05, (N_TAGS, len(anchors)))
    locator = SDPLocalizer(anchors, N_TAGS)
    ranges[2, 3] = np.nan
    with_nan, _ = locator.solve(ranges)
    ranges[2, 3] = 100.0
    with_outlier, _ = locator.solve(ranges)
    assert np.linalg.norm(with_outlier[2] - with_nan[2]) > 0.1
    np.testing.assert_allclose(with_nan[[0, 1, 3, 4]], with_outlier[[0, 1, 3, 4]], atol=1e-4)


def test_second_solve_reuses_problem_and_returns_new_answer(cvxpy):
    anchors, first = scene(6)
    _, second = scene(7)
    second = anchors.mean(axis=0) + 0.5 * (second - second.mean(axis=0))
    locator = SDPLocalizer(anchors, N_TAGS)
    problem = locator._problem
    assert problem.is_dpp()
    np.testing.assert_allclose(locator.solve(exact_ranges(anchors, first))[0], first, atol=1e-4)
    np.testing.assert_allclose(locator.solve(exact_ranges(anchors, second))[0], second, atol=1e-4)
    assert locator._problem is problem


def test_wrong_range_shape_is_rejected(cvxpy):
    anchors, _ = scene(8)
    with pytest.raises(ValueError, match='shape'):
        SDPLocalizer(anchors, N_TAGS).solve(np.ones((N_TAGS, len(anchors) - 1)))
    with pytest.raises(ValueError, match='shape'):
        SDPLocalizer(anchors[:, :2], N_TAGS)


def test_solver_failure_raises_with_status(cvxpy):
    anchors, tags = scene(9)
    locator = SDPLocalizer(anchors, N_TAGS)
    locator._problem = SimpleNamespace(solve=lambda **_: None, status='solver_error', value=None)
    with pytest.raises(RuntimeError, match='solver_error'):
        locator.solve(exact_ranges(anchors, tags))


def test_missing_cvxpy_gives_clear_import_error(monkeypatch):
    monkeypatch.setitem(sys.modules, 'cvxpy', None)
    with pytest.raises(ImportError, match=r'needs cvxpy: pip install cvxpy \(a benchmark extra\)'):
        SDPLocalizer(np.eye(4, 3), N_TAGS)


def test_package_import_does_not_import_cvxpy():
    code = ('import sys, epp_ros, epp_ros.core, epp_ros.core.solvers.sdp; '
            'print("cvxpy" in sys.modules)')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == 'False'
