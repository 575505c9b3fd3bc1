import numpy as np
import pytest

from epp_ros.core.plane import fit_slew, from_plane, project_ranges, to_plane

BASE = np.array([1.0, -2.0, 3.5])


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
