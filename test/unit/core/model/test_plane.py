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

from epp_ros.core.model.plane import (fit_plane_to_ranges, fit_slew, from_plane, project_ranges,
                                      to_plane)
from epp_ros.core.solvers import compiled
import numpy as np
import pytest

BASE = np.array([1.0, -2.0, 3.5])


@pytest.fixture(params=['compiled', 'numpy'])
def path(request, monkeypatch):
    """Run the plane fit compiled (``compiled_plane``), then in numpy."""
    monkeypatch.setattr(compiled, 'COMPILED', request.param == 'compiled')
    return request.param


@pytest.mark.parametrize('slew', [0.0, 0.3, np.pi / 2, -np.pi / 2, 2.5, -3.0])
def test_fit_slew_recovers_any_direction(slew):
    reach = np.array([2.0, 5.0, 9.0])
    points = BASE + np.column_stack([reach * np.cos(slew), reach * np.sin(slew),
                                     [1.0, 4.0, -2.0]])
    assert np.isclose(np.angle(np.exp(1j * (fit_slew(points, BASE) - slew))), 0.0,
                      atol=1e-12)


def test_plane_round_trip_and_distances():
    rng = np.random.default_rng(0)
    slew = 0.7
    coords = rng.uniform(-10, 10, (6, 2))
    points = from_plane(coords, BASE, slew)
    np.testing.assert_allclose(to_plane(points, BASE, slew), coords, atol=1e-12)
    np.testing.assert_allclose(fit_slew(points[coords[:, 0] > 0], BASE), slew, atol=1e-12)


def test_range_projection_is_exact_for_points_in_the_plane():
    rng = np.random.default_rng(1)
    slew = -1.1
    tags = from_plane(rng.uniform(1, 20, (5, 2)), BASE, slew)
    anchors = rng.uniform(-8, 8, (4, 3))
    ranges = np.linalg.norm(tags[:, None] - anchors[None], axis=-1)
    squared, clipped = project_ranges(ranges, anchors, BASE, slew)
    in_plane = to_plane(anchors, BASE, slew)
    expected = np.sum((to_plane(tags, BASE, slew)[:, None] - in_plane[None]) ** 2, axis=-1)
    np.testing.assert_allclose(squared, expected, rtol=1e-10, atol=1e-10)
    assert not clipped.any()


def test_range_projection_clips_impossible_ranges_and_keeps_missing():
    anchors = np.array([[0.0, 5.0, 0.0], [3.0, 0.0, 0.0]])
    ranges = np.array([[2.0, np.nan]])         # 2 m to an anchor 5 m off the plane
    squared, clipped = project_ranges(ranges, anchors, np.zeros(3), 0.0)
    assert squared[0, 0] == 0.0 and clipped[0, 0]
    assert np.isnan(squared[0, 1]) and not clipped[0, 1]


@pytest.mark.parametrize('with_lengths', [False, True])
def test_plane_fit_recovers_the_slew_of_exact_ranges(with_lengths, path):
    rng = np.random.default_rng(2)
    slew = 2.9
    coords = np.cumsum(rng.uniform(3, 6, (4, 2)), axis=0)          # a chain rising outward
    pivot = np.array([0.0, BASE[2]])
    lengths = np.linalg.norm(np.diff(np.vstack([pivot, coords]), axis=0), axis=1)
    anchors = np.column_stack([rng.uniform(-6, 6, (5, 2)), rng.uniform(0, 4, 5)])
    ranges = np.linalg.norm(from_plane(coords, BASE, slew)[:, None] - anchors[None], axis=-1)
    ranges[0, :3] = np.nan                     # a tag with two ranges still fits
    start = coords + rng.normal(0, 0.3, coords.shape)
    fitted_slew, fitted = fit_plane_to_ranges(
        start, ranges, anchors, BASE, slew - 0.05,
        *((pivot, lengths) if with_lengths else ()), max_iter=20, tol=1e-12)
    assert abs(fitted_slew - slew) < 1e-9
    np.testing.assert_allclose(fitted, coords, atol=1e-7)


def test_plane_fit_holds_a_tag_without_ranges(path):
    anchors = np.array([[5.0, 1.0, 0.0], [-3.0, 4.0, 1.0], [0.0, -5.0, 2.0], [2.0, 2.0, 6.0]])
    coords = np.array([[4.0, 6.0], [9.0, 8.0]])
    ranges = np.linalg.norm(from_plane(coords, BASE, 0.4)[:, None] - anchors[None], axis=-1)
    ranges[1] = np.nan
    start = coords + [[0.2, -0.1], [1.0, 1.0]]
    fitted_slew, fitted = fit_plane_to_ranges(start, ranges, anchors, BASE, 0.35, max_iter=20)
    assert np.all(np.isfinite(fitted)) and np.isfinite(fitted_slew)
    np.testing.assert_allclose(fitted[1], start[1])


def test_plane_fit_with_lengths_needs_the_pivot(path):
    with pytest.raises(ValueError, match='pivot'):
        fit_plane_to_ranges(np.ones((1, 2)), np.ones((1, 3)), np.zeros((3, 3)), BASE, 0.0,
                            arm_lengths=np.ones(1))


def noisy_plane_problem(seed):
    """Return a plane fit's arguments: tags in a plane, noisy ranges, some missing."""
    rng = np.random.default_rng(seed)
    slew = rng.uniform(-np.pi, np.pi)
    p, m = 2 + seed % 5, 3 + seed % 6
    coords = np.cumsum(rng.uniform(2, 8, (p, 2)) * [1.0, rng.choice([-1.0, 1.0])], axis=0)
    pivot = np.array([0.5, BASE[2]])
    lengths = np.linalg.norm(np.diff(np.vstack([pivot, coords]), axis=0), axis=1)
    anchors = np.column_stack([rng.uniform(-6, 6, (m, 2)), rng.uniform(0, 4, m)])
    ranges = np.linalg.norm(from_plane(coords, BASE, slew)[:, None] - anchors[None], axis=-1)
    ranges += rng.normal(0.0, 0.05, ranges.shape) + (rng.random(ranges.shape) < 0.1) * 2.0
    ranges[rng.random(ranges.shape) < 0.15] = np.nan
    start = coords + rng.normal(0, 0.5, coords.shape)
    sections = (pivot, lengths) if seed % 2 else ()
    return (start, ranges, anchors, BASE, slew + rng.normal(0, 0.05), *sections)


def test_the_compiled_plane_fit_is_the_numpy_fit_to_rounding(monkeypatch):
    for seed in range(80):
        arguments = noisy_plane_problem(seed)
        found = []
        for path in (True, False):
            monkeypatch.setattr(compiled, 'COMPILED', path)
            found.append(fit_plane_to_ranges(*arguments, max_iter=1 + seed % 6, tol=1e-10))
        (slew, coords), (expected_slew, expected) = found
        assert slew == pytest.approx(expected_slew, abs=1e-9)
        np.testing.assert_allclose(coords, expected, atol=1e-8)


def test_non_finite_coordinates_give_a_non_finite_fit_on_either_path(path):
    start, ranges, anchors, base, slew = noisy_plane_problem(2)
    start[0, 0] = np.nan
    fitted_slew, _ = fit_plane_to_ranges(start, ranges, anchors, base, slew, max_iter=3)
    assert not np.isfinite(fitted_slew)
