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

"""The paper's baselines behind PostureEstimator: SR-LS, SDP, TPSM."""
from epp_ros.core import PostureEstimator
from epp_ros.core.simulation.simulate import (AngleNoise, observe, random_posture, RangeNoise,
                                              truck_pump)
from epp_ros.core.solvers.multilateration import srls
import numpy as np
import pytest


def test_srls_method_is_srls_per_tag():
    model = truck_pump()
    rng = np.random.default_rng(1)
    joints = random_posture(model, rng)[2]
    ranges, _ = RangeNoise(sigma=0.3).apply(model.ranges(joints), rng)
    estimator = PostureEstimator(model, 'srls')
    estimator.update(ranges)
    estimate = estimator.last_diagnostics['estimate']     # judged or not: the method's
    expected = np.stack([srls(model.anchors, row) for row in ranges])
    np.testing.assert_allclose(estimate, expected, atol=1e-12)
    # No lengths imposed: noise stretches the sections.
    assert estimator.last_diagnostics['arm_length_error'].max() > 1e-3


def test_sdp_and_srls_agree_without_noise_and_differ_with_it():
    model = truck_pump()
    rng = np.random.default_rng(2)
    joints = random_posture(model, rng)[2]
    estimates = {m: PostureEstimator(model, m, sigma=1e-3).update(model.ranges(joints))
                 for m in ('srls', 'sdp')}
    for estimate in estimates.values():
        np.testing.assert_allclose(estimate, joints, atol=1e-4)
    noisy, _ = RangeNoise(sigma=0.5).apply(model.ranges(joints), rng)
    sdp = PostureEstimator(model, 'sdp', sigma=0.5)
    sdp.update(noisy)
    estimate = sdp.last_diagnostics['estimate']
    assert sdp.last_diagnostics['sdp_status'] in ('optimal', 'optimal_inaccurate')
    assert 0.01 < np.abs(estimate - joints).max() < 10.0


def test_per_tag_baselines_need_anchors_spanning_space():
    model = truck_pump()
    joints = random_posture(model, np.random.default_rng(3))[2]
    ranges = model.ranges(joints)
    ranges[2, [0, 1]] = np.nan            # tag 3 keeps four anchors that span space...
    for method in ('srls', 'sdp'):
        estimator = PostureEstimator(model, method)
        estimator.update(ranges)
        assert estimator.last_diagnostics['status'] == 'ok'
    ranges[2] = model.ranges(joints)[2]
    ranges[2, [0, 5]] = np.nan            # ...the four outriggers lie in one plane
    for method in ('srls', 'sdp'):
        estimator = PostureEstimator(model, method)
        assert np.all(np.isfinite(estimator.update(ranges)))
        assert estimator.last_diagnostics['status'] == 'insufficient_data'


def test_tpsm_is_the_forward_kinematics_of_the_angle_sensors():
    model = truck_pump()
    rng = np.random.default_rng(4)
    slew, pitches, joints = random_posture(model, rng)
    estimator = PostureEstimator(model, 'tpsm')
    np.testing.assert_allclose(estimator.update(model.ranges(joints), pitches=pitches,
                                                slew=slew), joints, atol=1e-12)
    assert estimator.last_diagnostics['ignored_inputs'] == ['ranges']
    # Errors accumulate along the chain: the tip is off most.
    frame, _ = observe(model, slew, pitches, rng, RangeNoise(), angle_noise=AngleNoise())
    error = np.linalg.norm(estimator.update(**frame) - joints, axis=1)
    assert error[-1] == error.max() > 0
    np.testing.assert_allclose(estimator.last_diagnostics['arm_length_error'], 0, atol=1e-12)


@pytest.mark.parametrize('missing', ['pitches', 'slew'])
def test_tpsm_without_every_angle_is_insufficient(missing):
    model = truck_pump()
    slew, pitches, joints = random_posture(model, np.random.default_rng(5))
    readings = {'pitches': pitches.copy(), 'slew': slew}
    if missing == 'pitches':
        readings['pitches'][2] = np.nan
    else:
        readings['slew'] = np.nan
    estimator = PostureEstimator(model, 'tpsm')
    assert np.all(np.isfinite(estimator.update(model.ranges(joints), **readings)))
    assert estimator.last_diagnostics['status'] == 'insufficient_data'
