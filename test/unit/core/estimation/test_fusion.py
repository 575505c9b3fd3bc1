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

"""Tag-tag ranges and angle sensors fused into the chain least squares; the turntable offset."""
from benchmarks.experiments import method_estimate
from epp_ros.core import BoomModel, PostureEstimator
from epp_ros.core.model.bounds import crlb, fisher_information
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation.simulate import (AngleNoise, observe, random_posture, RangeNoise,
                                              truck_pump, working_cycle)
from monte_carlo import assert_mse_at_bound, UNBIASED
import numpy as np
import pytest

NOISE = SensorNoise(range_sigma=0.1, tag_sigma=0.05, pitch_sigma=0.01, slew_sigma=0.02)

#: Noise-free frames, and the estimator told so: one frame then determines the posture.
EXACT = {'sigma': 1e-3, 'tag_sigma': 1e-3, 'pitch_sigma': 1e-5, 'slew_sigma': 1e-5,
         'nlos_fraction': 0.0}


def full_frame(model, slew, pitches, rng):
    """Every kind of measurement, noise-free, a few of each missing."""
    joints = model.forward_kinematics(slew, pitches)
    ranges = model.ranges(joints)
    ranges[rng.random(ranges.shape) < 0.2] = np.nan
    tag_ranges = np.linalg.norm(joints[:, None] - joints[None], axis=-1)
    tag_ranges[rng.random(tag_ranges.shape) < 0.5] = np.nan
    readings = pitches.copy()
    readings[1] = np.nan
    return Measurements.clean(model, ranges, tag_ranges, readings, slew)[0]


def test_residual_jacobian_matches_finite_differences_for_every_sensor():
    model = truck_pump()
    rng = np.random.default_rng(1)
    slew, pitches, _ = random_posture(model, rng)
    frame = full_frame(model, slew, pitches, rng)
    residuals = Residuals(model, frame, NOISE)
    assert residuals.size == frame.count() and residuals.n_ranged < residuals.size
    psi = np.r_[slew, pitches] + 0.05 * rng.standard_normal(6)
    step = 1e-6
    numeric = np.stack([(residuals.residuals(psi + step * e)[0]
                         - residuals.residuals(psi - step * e)[0]) / (2 * step)
                        for e in np.eye(psi.size)], axis=-1)
    np.testing.assert_allclose(residuals.jacobian(psi), numeric, rtol=1e-6, atol=1e-6)
    # At the truth every residual vanishes; an angle off by 2 pi is no error.
    np.testing.assert_allclose(residuals.residuals(np.r_[slew, pitches])[0], 0, atol=1e-9)
    np.testing.assert_allclose(residuals.residuals(np.r_[slew + 2 * np.pi, pitches])[0], 0,
                               atol=1e-9)


def test_fisher_information_of_all_sensors_matches_finite_differences():
    """F = sum over measurements of grad(h) grad(h)^T / sigma^2, from h by differences."""
    model = truck_pump()
    rng = np.random.default_rng(2)
    slew, pitches, _ = random_posture(model, rng)
    frame = full_frame(model, slew, pitches, rng)

    def predicted(angles):
        joints = model.forward_kinematics(angles[0], angles[1:])
        tags = np.linalg.norm(joints[:, None] - joints[None], axis=-1)
        return np.concatenate([model.ranges(joints)[np.isfinite(frame.ranges)],
                               tags[np.isfinite(frame.tag_ranges)],
                               angles[1:][np.isfinite(frame.pitches)], angles[:1]])

    sigma = np.concatenate([np.full(np.isfinite(frame.ranges).sum(), NOISE.range_sigma),
                            np.full(np.isfinite(frame.tag_ranges).sum(), NOISE.tag_sigma),
                            np.full(np.isfinite(frame.pitches).sum(), NOISE.pitch_sigma),
                            [NOISE.slew_sigma]])
    psi, step = np.r_[slew, pitches], 1e-6
    gradient = np.stack([(predicted(psi + step * e) - predicted(psi - step * e)) / (2 * step)
                         for e in np.eye(psi.size)], axis=-1) / sigma[:, None]
    np.testing.assert_allclose(fisher_information(model, slew, pitches, NOISE, frame),
                               gradient.T @ gradient, rtol=1e-6, atol=1e-6)


def test_every_extra_sensor_tightens_the_bound():
    model = truck_pump()
    slew, pitches, joints = random_posture(model, np.random.default_rng(3))
    ranges = model.ranges(joints)
    tag_ranges = np.linalg.norm(joints[:, None] - joints[None], axis=-1)
    bounds = [crlb(model, slew, pitches, NOISE, Measurements.clean(model, ranges, **extra)[0]).rmse
              for extra in ({}, {'tag_ranges': tag_ranges}, {'pitches': pitches},
                            {'pitches': pitches, 'slew': slew})]
    assert bounds[0] > bounds[1] and bounds[0] > bounds[2] > bounds[3] > 0
    # Ranges alone, the keyword forms agree with the plain (p, m) forms.
    assert bounds[0] == pytest.approx(crlb(model, slew, pitches, 0.1).rmse)


def test_fused_estimate_is_exact_without_noise_and_angles_alone_suffice():
    model = truck_pump()
    rng = np.random.default_rng(4)
    for _ in range(5):
        slew, pitches, joints = random_posture(model, rng)
        frame, _ = observe(model, slew, pitches, rng, RangeNoise(), RangeNoise(),
                           AngleNoise(0.0, 0.0))
        estimator = PostureEstimator(model, 'chain', **EXACT)
        np.testing.assert_allclose(estimator.update(**frame), joints, atol=1e-8)
        assert estimator.last_diagnostics['ignored_inputs'] == []
    # No UWB at all: the inclinometers and the encoder still give the posture.
    estimator = PostureEstimator(model, 'chain', **EXACT)
    estimate = estimator.update(np.full((5, 6), np.nan), pitches=pitches, slew=slew)
    assert estimator.last_diagnostics['status'] == 'ok'
    np.testing.assert_allclose(estimate, joints, atol=1e-8)


def test_fused_monte_carlo_rmse_matches_the_fused_bound():
    """Ranges, tag-tag ranges and angle sensors together: still efficient."""
    model = truck_pump()
    rng = np.random.default_rng(5)
    slew, pitches, joints = random_posture(model, rng)
    sigma, trials = 0.1, 300
    angles = AngleNoise(0.0, np.radians(1.0))     # Gaussian inclinometers only
    frames = [observe(model, slew, pitches, rng, RangeNoise(sigma=sigma),
                      RangeNoise(sigma=sigma), angles)[0] for _ in range(trials)]
    for frame in frames:
        frame.pop('slew')                         # no encoder: the slew from ranges
    noise = SensorNoise(sigma, sigma, angles.pitch_sigma)
    measured = Measurements.clean(model, **frames[0])[0]
    bound = crlb(model, slew, pitches, noise, measured)
    assert bound.rmse < crlb(model, slew, pitches, sigma).rmse
    estimator = PostureEstimator(model, 'chain', sigma=sigma, pitch_sigma=angles.pitch_sigma,
                                 **UNBIASED)
    squared = [np.sum((estimator.update(**frame) - joints) ** 2) / 5 for frame in frames]
    assert_mse_at_bound(squared, bound.rmse, estimator)


def test_a_too_long_tag_tag_range_is_flagged_as_nlos():
    model = truck_pump()
    rng = np.random.default_rng(6)
    slew, pitches, joints = random_posture(model, rng)
    frame, _ = observe(model, slew, pitches, rng, RangeNoise(sigma=0.02), RangeNoise(sigma=0.02))
    frame['tag_ranges'][2, 3] += 2.0
    estimator = PostureEstimator(model, 'chain', sigma=0.02)
    estimator.update(**frame)
    flags = estimator.last_diagnostics['nlos_tag_links']
    assert flags.shape == (5, 5) and {tuple(i) for i in np.argwhere(flags)} == {(2, 3)}
    assert not estimator.last_diagnostics['nlos_links'].any()


def test_multiplicative_noise_option_weights_long_ranges_less():
    model = truck_pump()
    rng = np.random.default_rng(7)
    slew, pitches, joints = random_posture(model, rng)
    eta = 0.02
    sigmas = eta * model.ranges(joints)
    bound = crlb(model, slew, pitches, sigmas)
    errors = {}
    for options in ({'sigma': 1e-3, 'eta': eta}, {'sigma': 0.3}):
        estimator = PostureEstimator(model, 'chain', **options)
        estimator.update(model.ranges(joints))
        errors[len(options)] = np.mean([np.sum((method_estimate(estimator, {
            'ranges': RangeNoise(eta=eta).apply(model.ranges(joints), rng)[0]}) - joints) ** 2)
            / 5 for _ in range(300)])
    assert np.sqrt(errors[2]) < 1.1 * bound.rmse
    assert errors[2] < errors[1]


def test_bad_extra_inputs_raise_clear_errors():
    estimator = PostureEstimator(truck_pump(), 'chain')
    ranges = np.full((5, 6), 10.0)
    with pytest.raises(ValueError, match='tag_ranges'):
        estimator.update(ranges, tag_ranges=np.zeros((5, 4)))
    with pytest.raises(ValueError, match='pitches'):
        estimator.update(ranges, pitches=[0.1, 0.2])
    with pytest.raises(ValueError, match='slew'):
        estimator.update(ranges, slew='north')
    with pytest.raises(ValueError, match='pitch_sigma'):
        PostureEstimator(truck_pump(), 'chain', pitch_sigma=0.0)


def test_extra_inputs_a_method_cannot_use_are_reported():
    model = truck_pump()
    slew, pitches, joints = random_posture(model, np.random.default_rng(8))
    estimator = PostureEstimator(model, 'cepp')
    estimator.update(model.ranges(joints), pitches=pitches, slew=slew)
    assert estimator.last_diagnostics['ignored_inputs'] == ['pitches', 'slew']


@pytest.mark.parametrize('method', ['epp2', 'cepp'])
def test_edm_methods_use_tag_tag_ranges(method):
    """Tag-tag ranges fill G's tag-tag block: with no prior weight they still place tags."""
    model = truck_pump()
    rng = np.random.default_rng(9)
    slew, pitches, joints = random_posture(model, rng)
    tag_ranges = np.linalg.norm(joints[:, None] - joints[None], axis=-1)
    estimator = PostureEstimator(model, method)
    estimate = estimator.update(model.ranges(joints), tag_ranges=tag_ranges)
    assert estimator.last_diagnostics['ignored_inputs'] == []
    np.testing.assert_allclose(estimate, joints, atol=1e-5)


# -- the pivot off the slew axis ------------------------------------------------------------
def offset_pump(offset=0.9):
    pump = truck_pump()
    return BoomModel(pump.arm_lengths, pump.base, pump.anchors, pivot_offset=offset)


def test_pivot_moves_on_a_circle_and_kinematics_follow_it():
    model = offset_pump(0.9)
    for slew in np.linspace(-np.pi, np.pi, 7):
        pivot = model.pivot(slew)
        assert np.hypot(*(pivot - model.base)[:2]) == pytest.approx(0.9)
        assert pivot[2] == model.base[2]
        joints = model.forward_kinematics(slew, np.full(5, 0.3))
        np.testing.assert_allclose(model.section_lengths(joints), model.arm_lengths)
        np.testing.assert_allclose(model.pivot_of(joints), pivot, atol=1e-12)
        np.testing.assert_allclose(joints[0] - pivot, 9.0 * np.array(
            [np.cos(0.3) * np.cos(slew), np.cos(0.3) * np.sin(slew), np.sin(0.3)]), atol=1e-12)
    assert model.base_anchor() is None                  # the pivot is not a fixed point
    psi = np.array([0.4, 0.5, 0.1, -0.2, 0.3, -0.4])

    def joints(angles):
        return model.forward_kinematics(angles[0], angles[1:])

    numeric = np.stack([(joints(psi + 1e-6 * e) - joints(psi - 1e-6 * e)) / 2e-6
                        for e in np.eye(6)], axis=-1)
    np.testing.assert_allclose(model.joint_jacobian(psi[0], psi[1:]), numeric, atol=1e-6)


@pytest.mark.parametrize('method', ['chain', 'cepp', 'epp2'])
def test_offset_pivot_is_tracked_exactly(method):
    """With the offset modelled, noise-free ranges give the exact posture on a slewing cycle."""
    model = offset_pump(0.9)
    trajectory = working_cycle(model, 8.0, 5.0, rng=np.random.default_rng(10))
    estimator = PostureEstimator(model, method, tol=1e-10,
                                 **({'slew_iterations': 10, 'slew_tol': 1e-10}
                                    if method == 'cepp' else {}))
    for joints in trajectory.joints:
        estimate = estimator.update(model.ranges(joints))
        assert estimator.last_diagnostics['status'] == 'ok'
        # EPP2 places the pivot at the previous frame's slew: off by the slew step.
        tolerance = {'chain': 1e-6, 'cepp': 1e-4, 'epp2': 3e-3}[method]
        np.testing.assert_allclose(estimate, joints, atol=tolerance)


def test_ignoring_the_offset_costs_accuracy():
    truth_model, wrong_model = offset_pump(0.9), truck_pump()
    rng = np.random.default_rng(11)
    errors = {}
    postures = [random_posture(truth_model, rng)[2] for _ in range(5)]
    for name, model in (('modelled', truth_model), ('ignored', wrong_model)):
        errors[name] = max(np.abs(method_estimate(PostureEstimator(model, 'chain', **EXACT),
                                                  {'ranges': truth_model.ranges(joints)})
                                  - joints).max() for joints in postures)
    assert errors['modelled'] < 1e-6 < 0.1 < errors['ignored']
