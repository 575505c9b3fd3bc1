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

"""The method interface and the per-frame result, made explicit."""
from epp_ros.app.health import grade, WARN
from epp_ros.core import METHODS, PostureEstimator
from epp_ros.core.estimation.noise_learning import RangeNoiseEstimate
from epp_ros.core.estimation.posture_method import FrameResult, PostureMethod
from epp_ros.core.simulation.simulate import truck_pump
from monte_carlo import UNBIASED
import numpy as np
import pytest

MODEL = truck_pump()


@pytest.mark.parametrize('method', sorted(METHODS))
def test_every_method_is_a_posture_method(method):
    assert isinstance(METHODS[method](MODEL), PostureMethod)


def test_a_frame_result_reads_as_the_mapping_it_always_was():
    noise = RangeNoiseEstimate(0.1, 0.0, 0.1, 1.0)
    result = FrameResult.from_values({'status': 'ok', 'valid': True, 'level': 0,
                                      'message': 'tracking', 'method': 'chain',
                                      'cold_start': False, 'reacquired': False,
                                      'noise': noise, 'chi_square': 3.5,
                                      'hypotheses': 2})
    assert result.valid and result['valid'] and result['chi_square'] == 3.5
    assert result.chi_square == 3.5 and result['hypotheses'] == 2
    assert result.details == {'hypotheses': 2}      # a method's extra; the rest typed
    assert 'estimate' not in result and result.get('estimate') is None   # nothing solved
    assert 'converged' not in result and len(result) == len(dict(result)) == 10
    with pytest.raises(KeyError):
        result['rmse']


def test_converged_is_true_only_when_it_is():
    """One iteration from the last frame's posture does not reach this frame's."""
    slew, pitches = 0.4, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])
    moved = MODEL.ranges(MODEL.forward_kinematics(slew + 0.05, pitches + 0.05))
    for max_iter, converged in ((1, False), (50, True)):
        estimator = PostureEstimator(MODEL, 'chain', **UNBIASED)
        estimator.update(MODEL.ranges(MODEL.forward_kinematics(slew, pitches)))
        estimator.reconfigure(max_iter=max_iter)
        estimator.update(moved)
        assert estimator.last_diagnostics['converged'] is converged
        assert (grade(estimator.last_diagnostics)[0] >= WARN) is not converged


@pytest.mark.parametrize('method', ['chain', 'cepp', 'track'])
def test_reset_seeds_the_next_frame_and_checks_the_seed(method):
    slew, pitches = 0.4, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])
    joints = MODEL.forward_kinematics(slew, pitches)
    estimator = PostureEstimator(MODEL, method)
    estimator.reset(joints)
    estimator.update(MODEL.ranges(joints))
    assert not estimator.last_diagnostics['cold_start']
    np.testing.assert_allclose(estimator.last_diagnostics['estimate'], joints, atol=1e-6)
    for bad in (joints[:3], np.full((5, 3), np.nan)):
        with pytest.raises(ValueError, match='joints'):
            estimator.reset(bad)
    estimator.reset()
    estimator.update(MODEL.ranges(joints))
    assert estimator.last_diagnostics['cold_start']


def test_a_frames_figures_are_typed_fields_and_details_keep_only_the_extras():
    slew, pitches = 0.4, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])
    estimator = PostureEstimator(MODEL, 'chain', **UNBIASED)
    estimator.update(MODEL.ranges(MODEL.forward_kinematics(slew, pitches)))
    result = estimator.last_diagnostics
    p, m = MODEL.n_sections, MODEL.n_anchors
    assert result.valid and result.missing_links == 0 and result.implausible_links == 0
    assert result.joint_std.shape == (p,) and np.all(result.joint_std > 0)
    assert 0 < result.predicted_rmse < 0.5 and result.range_residual_rms < 1e-6
    assert result.section_lengths.shape == result.arm_length_error.shape == (p,)
    assert result.nlos_links.shape == (p, m) and result.range_bias.shape == (2,)
    assert result.iterations >= 1 and result.solve_time > 0 and result.anchor_shifts == {}
    typed = {name for name in result.__dataclass_fields__ if name != 'details'}
    assert not typed & set(result.details)
    assert result['predicted_rmse'] == result.predicted_rmse     # and still a mapping
