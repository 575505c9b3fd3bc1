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

from dataclasses import replace

from epp_ros.app.health import (assess, ERROR, joint_stds, nlos_pairs, nlos_text, OK, Thresholds,
                                WARN)
from epp_ros.core import PostureEstimator
from epp_ros.core.simulation.simulate import random_posture, RangeNoise, truck_pump
from monte_carlo import UNBIASED
import numpy as np
import pytest

MODEL = truck_pump()
JOINTS = random_posture(MODEL, np.random.default_rng(0))[2]


def diagnostics_of(method, ranges, **options):
    estimator = PostureEstimator(MODEL, method, **options)
    estimator.update(ranges)
    return estimator.last_diagnostics


def test_good_fit_is_ok_with_the_paper_diagnostic():
    level, message, values = assess(diagnostics_of('cepp', MODEL.ranges(JOINTS), **UNBIASED),
                                    MODEL.arm_lengths)
    assert level == OK and message == 'tracking'
    assert float(values['section 1 abs error [m]']) < 1e-6
    assert values['section 1 configured [m]'] == '9.0000'


def test_chain_reports_its_predicted_uncertainty_and_nlos():
    ranges = MODEL.ranges(JOINTS)
    ranges[4, 1] += 5.0
    _, _, values = assess(diagnostics_of('chain', ranges), MODEL.arm_lengths)
    assert float(values['predicted RMSE [m]']) > 0
    assert 'joint 5 predicted std [m]' in values and values['NLOS links'] == '1'


def test_the_variance_factor_that_widened_the_stds_is_reported():
    exact = diagnostics_of('chain', MODEL.ranges(JOINTS), sigma=0.1)
    assert assess(exact, MODEL.arm_lengths)[2]['variance factor'] == '1.00'
    # Every range 0.3 m off at random, told 0.1 m: larger residuals than the noise told.
    ranges = RangeNoise(sigma=0.3).apply(MODEL.ranges(JOINTS), np.random.default_rng(3))[0]
    noisy = diagnostics_of('chain', ranges, sigma=0.1, learn_noise=False, **UNBIASED)
    values = assess(noisy, MODEL.arm_lengths)[2]
    assert float(values['variance factor']) == pytest.approx(
        noisy.chi_square / noisy.chi_square_dof, abs=0.005)
    assert float(values['variance factor']) > 2.0


def test_the_links_judged_nlos_are_named_joint_then_anchor():
    ranges = MODEL.ranges(JOINTS)
    ranges[4, 1] += 5.0                         # joint 5's tag to anchor 2
    ranges[1, 2] += 6.0                         # joint 2's tag to anchor 3
    _, _, values = assess(diagnostics_of('chain', ranges), MODEL.arm_lengths)
    assert values['NLOS links'] == '2' and values['NLOS flagged links'] == '2:3 5:2'
    assert values['outlier links'] == '0' and values['outlier flagged links'] == ''
    # Joint 4's tag to anchor 5, 1 m short of the frame before: no noise explains it.
    estimator = PostureEstimator(MODEL, 'track')
    estimator.update(MODEL.ranges(JOINTS))
    short = MODEL.ranges(JOINTS)
    short[3, 4] -= 1.0
    estimator.update(short)
    _, _, values = assess(estimator.last_diagnostics, MODEL.arm_lengths)
    assert values['outlier links'] == '1' and values['outlier flagged links'] == '4:5'
    _, _, values = assess(diagnostics_of('chain', MODEL.ranges(JOINTS)), MODEL.arm_lengths)
    assert values['NLOS links'] == '0' and values['NLOS flagged links'] == ''
    blocked = np.zeros((5, 6), dtype=bool)
    blocked[[0, 4], [5, 0]] = True
    assert nlos_text(blocked) == '1:6 5:1'
    assert nlos_text(np.zeros(0)) == ''


def test_what_the_node_reports_the_tools_read_back():
    ranges = MODEL.ranges(JOINTS)
    ranges[1, 2] += 6.0
    diagnostics = diagnostics_of('chain', ranges)
    _, _, values = assess(diagnostics, MODEL.arm_lengths)
    assert nlos_pairs(values['NLOS flagged links']) == [(2, 3)]
    np.testing.assert_allclose(joint_stds(values, 5), diagnostics['joint_std'], atol=1e-4)
    # A motion model's own uncertainty is preferred to the bound's; unknown is NaN.
    tracked = replace(diagnostics, details={**diagnostics.details,
                                            'posterior_joint_std': [0.5] * 5})
    _, _, values = assess(tracked, MODEL.arm_lengths)
    assert np.isnan(joint_stds(values, 6)[5])
    assert joint_stds(values, 5) == [0.5] * 5


def test_levels_follow_the_thresholds():
    ranges, _ = RangeNoise(sigma=0.1).apply(MODEL.ranges(JOINTS), np.random.default_rng(2))
    rmse = diagnostics_of('chain', ranges)['predicted_rmse']
    for warn, level in ((2 * rmse, OK), (0.5 * rmse, WARN)):
        thresholds = Thresholds(predicted_rmse_warn=warn, predicted_rmse_error=4 * rmse)
        assert assess(diagnostics_of('chain', ranges, thresholds=thresholds),
                      MODEL.arm_lengths)[0] == level
    thresholds = Thresholds(predicted_rmse_warn=0.2 * rmse, predicted_rmse_error=0.5 * rmse)
    diagnostics = diagnostics_of('chain', ranges, thresholds=thresholds)
    assert not diagnostics['valid'] and diagnostics['status'] == 'unobservable'
    assert assess(diagnostics, MODEL.arm_lengths)[0] == ERROR
    diagnostics = replace(diagnostics_of('epp2', MODEL.ranges(JOINTS)), converged=False)
    assert assess(diagnostics, MODEL.arm_lengths)[:2] == (
        WARN, 'solver stopped before converging')


def test_thresholds_are_finite_positive_and_a_warn_above_its_error_never_warns():
    for bad in ({'residual_warn': float('nan')}, {'arm_length_error': -1.0},
                {'predicted_rmse_error': float('inf')}):
        with pytest.raises(ValueError, match=list(bad)[0].rsplit('_', 1)[0]):
            Thresholds(**bad)
    rmse = diagnostics_of('cepp', MODEL.ranges(JOINTS))['predicted_rmse']
    for error, level in ((0.5 * rmse, ERROR), (0.8 * rmse, ERROR), (1.2 * rmse, OK)):
        thresholds = Thresholds(predicted_rmse_warn=1.5 * error, predicted_rmse_error=error)
        diagnostics = diagnostics_of('cepp', MODEL.ranges(JOINTS), thresholds=thresholds)
        assert assess(diagnostics, MODEL.arm_lengths)[0] == level


def test_epp1_is_judged_on_the_lengths_it_does_not_hold():
    ranges, _ = RangeNoise(sigma=0.3).apply(MODEL.ranges(JOINTS), np.random.default_rng(1))
    diagnostics = diagnostics_of('epp1', ranges, sigma=0.3)
    error = np.max(diagnostics['arm_length_error'])
    level = assess(diagnostics, MODEL.arm_lengths)[0]
    assert error > Thresholds().arm_length_warn and level >= WARN
    assert (level == ERROR) == (error > Thresholds().arm_length_error or
                                not diagnostics['valid'])


def test_an_unsolved_frame_is_an_error():
    level, message, _ = assess(diagnostics_of('cepp', np.full((5, 6), np.nan)),
                               MODEL.arm_lengths)
    assert level == ERROR and 'insufficient_data' in message
