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

"""A frame's measurements and residuals: what is validated, and how the rows are stacked."""
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation import truck_pump
import numpy as np
import pytest

MODEL = truck_pump()


@pytest.mark.parametrize('bad', [0.0, -0.1, float('nan'), float('inf'), -1,
                                 np.array([0.1, np.nan]), np.array([[0.1, 0.0]]), 'metre'])
@pytest.mark.parametrize('field', ['range_sigma', 'tag_sigma', 'pitch_sigma', 'slew_sigma'])
def test_a_sigma_that_is_no_standard_deviation_is_refused(field, bad):
    with pytest.raises(ValueError, match=field):
        SensorNoise(**{field: bad})


@pytest.mark.parametrize('good', [0.1, 1, np.float64(0.2), np.full((5, 6), 0.3)])
def test_a_positive_sigma_is_taken_as_given(good):
    assert SensorNoise(range_sigma=good).range_sigma is good


def _frame():
    joints = MODEL.forward_kinematics(0.3, np.array([0.6, 0.2, -0.1, -0.4, -0.6]))
    ranges = MODEL.ranges(joints)
    ranges[1, 2] = ranges[4, 0] = np.nan
    tag_ranges = np.full((5, 5), np.nan)
    tag_ranges[0, 2] = np.linalg.norm(joints[0] - joints[2])
    pitches = np.array([0.6, np.nan, -0.1, np.nan, np.nan])
    return Measurements(ranges, tag_ranges, pitches, 0.3), ranges


@pytest.mark.parametrize('slew', [0.3, np.nan])
def test_rows_are_links_then_tag_links_then_angles(slew):
    frame, ranges = _frame()
    frame = Measurements(frame.ranges, frame.tag_ranges, frame.pitches, slew)
    link_sigma = np.linspace(0.05, 0.2, ranges.size).reshape(ranges.shape)
    residuals = Residuals(MODEL, frame, SensorNoise(link_sigma, tag_sigma=0.07,
                                                    pitch_sigma=0.01, slew_sigma=0.02))
    measured = np.isfinite(ranges)
    angles = [0.6, -0.1] + ([0.3] if np.isfinite(slew) else [])
    np.testing.assert_array_equal(residuals.measured, np.concatenate(
        [ranges[measured], frame.tag_ranges[0, 2:3], angles]))
    np.testing.assert_array_equal(residuals.sigma, np.concatenate(
        [link_sigma[measured], [0.07, 0.01, 0.01] + ([0.02] if np.isfinite(slew) else [])]))
    assert residuals.n_ranged == measured.sum() + 1
    expected_rows = [[0, 1, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0]] + (
        [[1, 0, 0, 0, 0, 0]] if np.isfinite(slew) else [])
    assert residuals.rows(np.r_[0.3, 0.6, 0.2, -0.1, -0.4, -0.6])[-len(angles):].tolist() \
        == expected_rows
    assert residuals.layout[4].dtype == np.int64


def test_a_scalar_sigma_and_a_row_of_sigmas_broadcast_as_the_full_matrix():
    frame, ranges = _frame()
    full = Residuals(MODEL, frame, SensorNoise(np.full(ranges.shape, 0.15)))
    scalar = Residuals(MODEL, frame, SensorNoise(0.15))
    per_anchor = np.linspace(0.1, 0.2, ranges.shape[1])
    row = Residuals(MODEL, frame, SensorNoise(per_anchor))
    np.testing.assert_array_equal(scalar.sigma, full.sigma)
    np.testing.assert_array_equal(row.sigma[:row.n_ranged - 1],
                                  np.broadcast_to(per_anchor, ranges.shape)[np.isfinite(ranges)])
