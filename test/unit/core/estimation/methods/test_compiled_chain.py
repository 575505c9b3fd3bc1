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

"""The chain's compiled fit against its numpy reference: the same fits, to rounding."""
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.methods.chain import angles_from_joints, ChainMethod
from epp_ros.core.estimation.methods.track import Hypothesis, TrackMethod
from epp_ros.core.model.measurements import Measurements
from epp_ros.core.simulation.simulate import (field_effects, make_motion, random_posture,
                                              simulate_field, truck_pump)
from epp_ros.core.solvers import compiled as compiled_gate
import numpy as np
import pytest


@pytest.fixture
def paths(monkeypatch):
    """Return a function that runs its argument with the chain compiled and with numpy."""
    def both(run):
        results = []
        for compiled in (True, False):
            monkeypatch.setattr(compiled_gate, 'COMPILED', compiled)
            results.append(run())
        return results
    return both


def _frames(rng, count=12):
    """Frames of every kind of row: tag-tag ranges, angles, missing links, long ranges."""
    model = truck_pump()
    p, m = model.n_sections, model.n_anchors
    for index in range(count):
        slew, pitches, joints = random_posture(model, rng)
        ranges = model.ranges(joints) + rng.normal(0.0, 0.1, (p, m))
        ranges[rng.random((p, m)) < 0.15] = np.nan
        ranges[rng.random((p, m)) < 0.1] += rng.uniform(0.5, 4.0)        # blocked
        ranges[rng.random((p, m)) < 0.05] -= rng.uniform(1.0, 3.0)       # short outliers
        tag_ranges = np.full((p, p), np.nan)
        if index % 2:
            between = np.linalg.norm(joints[:, None] - joints[None], axis=-1)
            tag_ranges[np.triu_indices(p, 1)] = between[np.triu_indices(p, 1)] + 0.05
        angles = index % 3 == 0
        yield model, joints, Measurements(
            ranges, tag_ranges, pitches + 0.01 if angles else np.full(p, np.nan),
            slew + 0.01 if angles else np.nan)


@pytest.mark.parametrize('options', [{}, {'nlos_fraction': 0.0}, {'lowest_joint': 12.0},
                                     {'eta': 0.01, 'link_bias_std': 0.1}])
def test_each_fit_is_the_numpy_fit_to_rounding(paths, options):
    rng = np.random.default_rng(7)
    fits = 0
    for model, joints, measurements in _frames(rng):
        method = ChainMethod(model, **options)
        residuals = method.residuals_of(measurements)
        start = np.r_[angles_from_joints(model, joints + rng.normal(0.0, 0.5, joints.shape))]
        compiled, reference = paths(lambda: method.cost(start, residuals))
        assert compiled == pytest.approx(reference, rel=1e-12)
        for judged in (False, True):
            for max_iter, stall in ((None, 1e-6), (4, 1e-6), (50, 0.0)):
                compiled, reference = paths(lambda: method._levenberg_marquardt(
                    start, residuals, judged, max_iter, stall))
                # Where a fit stops on ``stall``, rounding may stop the other a step away:
                # within the stall of the cost, a micro-radian at most; and a fit to its
                # tolerance stops where rounding leaves the cost flat.
                atol = 1e-7 if stall == 0.0 else 1e-6
                np.testing.assert_allclose(compiled.x, reference.x, rtol=0, atol=atol)
                assert compiled.cost == pytest.approx(reference.cost, rel=max(stall, 1e-9))
                np.testing.assert_allclose(compiled.state, reference.state, atol=1e3 * atol)
                # At the minimum, rounding decides whether one more tiny step is taken.
                assert compiled.converged == reference.converged
                if not reference.converged:
                    assert compiled.iterations == reference.iterations
                fits += 1
    assert fits == 12 * 6


def test_each_tracker_update_is_the_numpy_update_to_rounding(paths):
    """Tags ranging at their own times, the prediction's prior, both losses, the ground."""
    rng = np.random.default_rng(11)
    updates = 0
    for model, joints, measurements in _frames(rng, count=8):
        track = TrackMethod(model, lowest_joint=float(rng.choice([-0.5, 12.0])))
        residuals = track.chain.residuals_of(measurements)
        n = model.n_sections + 1
        psi = np.r_[angles_from_joints(model, joints + rng.normal(0.0, 0.3, joints.shape))]
        spread = rng.normal(0.0, 0.1, (2 * n, 2 * n))
        predicted = Hypothesis(np.r_[psi, rng.normal(0.0, 0.1, n)],
                               spread @ spread.T + np.eye(2 * n) * 1e-3)
        delays = rng.uniform(-0.1, 0.0, model.n_sections)
        for max_iter in (None, 3):
            compiled, reference = paths(lambda: track._update(predicted, residuals, delays,
                                                              max_iter))
            (fitted, iterations, converged, surprise) = compiled
            (expected, expected_iterations, expected_converged, expected_surprise) = reference
            np.testing.assert_allclose(fitted.state, expected.state, rtol=0, atol=1e-6)
            np.testing.assert_allclose(fitted.covariance, expected.covariance, rtol=1e-5,
                                       atol=1e-12)
            assert fitted.log_weight == pytest.approx(expected.log_weight, rel=1e-6)
            assert surprise == pytest.approx(expected_surprise, rel=1e-4, abs=1e-9)
            assert converged == expected_converged
            if max_iter is not None:
                assert iterations == expected_iterations
            updates += 1
    assert updates == 16


@pytest.mark.parametrize('method', ['chain', 'track', 'cepp'])
@pytest.mark.parametrize('case', ['real_uwb',
                                  'nlos_persistent,dropouts,tdma,inclinometer_bias'])
def test_an_estimator_publishes_the_same_frames_either_way(paths, method, case):
    model = truck_pump()
    rng = np.random.default_rng(3)
    frames = simulate_field(model, make_motion('working', model, 12.0, rng), 12.0,
                            field_effects(case), rng)

    def run():
        estimator = PostureEstimator(model, method)
        out = []
        for frame in frames:
            joints = estimator.update(**frame.inputs())
            result = estimator.last_diagnostics
            out.append((joints, result.status, result.predicted_rmse))
        return out

    compiled, reference = paths(run)
    assert [status for _, status, _ in compiled] == [status for _, status, _ in reference]
    for (joints, _, rmse), (expected, _, expected_rmse) in zip(compiled, reference):
        np.testing.assert_allclose(joints, expected, atol=1e-8)
        assert (rmse is None) == (expected_rmse is None)
        if rmse is not None:
            # A frame a silent tag leaves unobservable predicts tens of km: that bound
            # moves with the posture's last digits.
            assert rmse == pytest.approx(expected_rmse, rel=1e-3 if rmse > 100.0 else 1e-6)
