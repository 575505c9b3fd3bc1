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

"""The posterior Cramér–Rao bound of a motion model."""
from epp_ros.core.model.bounds import (bias_covariance, bound_from_covariance, crlb,
                                       fisher_information, POORLY_CONTROLLED, posterior_crlb,
                                       posterior_information, RangeBiasPrior,
                                       uncontrolled_covariance)
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation.simulate import random_posture, truck_pump, working_cycle
import numpy as np
import pytest
from scipy.optimize import least_squares

DT = 0.5


def constant_velocity(dt, q, size=1):
    """Return F and Q of ``size`` independent constant-velocity angles."""
    identity = np.eye(size)
    transition = np.block([[identity, dt * identity], [0 * identity, identity]])
    process = np.kron(np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]]),
                      np.diag(np.broadcast_to(q, (size,))))
    return transition, process


def kalman_covariances(transition, process, observation, noise, prior, frames):
    """Return the Kalman filter's posterior covariance after each frame, (frames, n, n)."""
    covariance, out = prior, []
    for k in range(frames):
        if k:
            covariance = transition @ covariance @ transition.T + process
        gain = covariance @ observation.T @ np.linalg.inv(
            observation @ covariance @ observation.T + noise)
        covariance = covariance - gain @ observation @ covariance
        out.append(covariance)
    return np.array(out)


def test_linear_gaussian_kalman_filter_attains_the_posterior_bound():
    transition, process = constant_velocity(DT, 0.3)
    observation, noise = np.array([[1.0, 0.0]]), np.array([[0.8 ** 2]])
    mean, prior = np.array([1.0, 0.5]), np.diag([4.0, 1.0])
    frames, trials = 30, 20000
    information = posterior_information(
        transition, process,
        np.broadcast_to(observation.T @ observation / noise[0, 0], (frames, 2, 2)),
        np.linalg.inv(prior))
    bound = np.linalg.inv(information)

    rng = np.random.default_rng(7)
    state = rng.multivariate_normal(mean, prior, trials)
    estimate, covariance = np.tile(mean, (trials, 1)), prior
    for k in range(frames):
        if k:
            state = state @ transition.T + rng.multivariate_normal([0, 0], process, trials)
            estimate = estimate @ transition.T
            covariance = transition @ covariance @ transition.T + process
        measured = state @ observation.T + rng.normal(0.0, np.sqrt(noise[0, 0]), (trials, 1))
        gain = covariance @ observation.T @ np.linalg.inv(
            observation @ covariance @ observation.T + noise)
        estimate = estimate + (measured - estimate @ observation.T) @ gain.T
        covariance = covariance - gain @ observation @ covariance
        # The filter's own covariance is the bound, and so is its empirical error covariance.
        np.testing.assert_allclose(covariance, bound[k], rtol=1e-9)
        error = estimate - state
        empirical = error.T @ error / trials
        expected = bound[k]
        standard_error = np.sqrt((expected ** 2 + np.outer(np.diag(expected), np.diag(expected)))
                                 / (trials - 1))
        assert np.all(np.abs(empirical - expected) <= 5 * standard_error), k


def test_information_form_equals_covariance_form():
    rng = np.random.default_rng(8)
    n, frames = 4, 12
    transition = np.eye(n) + 0.3 * rng.standard_normal((n, n))
    root = rng.standard_normal((n, n))
    process = root @ root.T + 0.1 * np.eye(n)
    rows = rng.standard_normal((frames, 2, n))
    measurement = rows.transpose(0, 2, 1) @ rows
    prior = np.eye(n) * 0.5
    information = posterior_information(transition, process, measurement, prior)
    expected = prior + measurement[0]
    for k in range(frames):
        if k:
            expected = np.linalg.inv(transition @ np.linalg.inv(expected) @ transition.T
                                     + process) + measurement[k]
        np.testing.assert_allclose(information[k], expected, rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(information[k], information[k].T)


def test_singular_process_noise_matches_the_kalman_filter():
    transition = constant_velocity(DT, 0.0)[0]
    shape = np.array([[DT ** 2 / 2], [DT]])
    process = 0.4 * shape @ shape.T                     # rank 1: a piecewise-constant jerk
    observation, noise = np.array([[1.0, 0.0]]), np.array([[0.25]])
    prior = np.diag([2.0, 3.0])
    frames = 25
    information = posterior_information(
        transition, process,
        np.broadcast_to(observation.T @ observation / noise[0, 0], (frames, 2, 2)),
        np.linalg.inv(prior))
    np.testing.assert_allclose(
        np.linalg.inv(information),
        kalman_covariances(transition, process, observation, noise, prior, frames),
        rtol=1e-9)
    # No process noise: information is only moved by the motion, J+ = F^-T J F^-1 + M.
    still = posterior_information(transition, np.zeros((2, 2)),
                                  np.broadcast_to(np.eye(2), (3, 2, 2)), np.zeros((2, 2)))
    inverse = np.linalg.inv(transition)
    np.testing.assert_allclose(still[1], inverse.T @ still[0] @ inverse + np.eye(2), rtol=1e-12)


def test_flat_prior_starts_from_the_first_frame_alone():
    transition, process = constant_velocity(DT, 0.3)
    measurement = np.broadcast_to(np.diag([1 / 0.64, 0.0]), (20, 2, 2))
    information = posterior_information(transition, process, measurement, np.zeros((2, 2)))
    np.testing.assert_array_equal(information[0], measurement[0])      # singular, and exact
    assert np.all(np.linalg.eigvalsh(information[1]) > 0)                # two positions fix v
    # A Kalman filter started from a nearly flat prior converges to the same information.
    nearly_flat = kalman_covariances(transition, process, np.array([[1.0, 0.0]]),
                                     np.array([[0.64]]), 1e9 * np.eye(2), 20)
    # The 1e9 prior costs the filter 1e9 * eps of round-off in its first update; 100 of it.
    np.testing.assert_allclose(np.linalg.inv(information[1:]), nearly_flat[1:],
                               rtol=100 * 1e9 * np.finfo(float).eps)


def test_constant_measurements_reach_a_steady_state_below_one_frame():
    model = truck_pump()
    trajectory = working_cycle(model, 1.0, 1.0)
    slew, pitches = trajectory.slew[0], trajectory.pitches[0]
    size, dt, frames = model.n_sections + 1, 0.1, 300
    single = fisher_information(model, slew, pitches, 0.1)
    measurement = np.zeros((frames, 2 * size, 2 * size))
    measurement[:, :size, :size] = single
    information = posterior_information(*constant_velocity(dt, 1e-2, size), measurement,
                                        np.zeros((2 * size, 2 * size)))
    scale = np.abs(information[-1]).max()
    assert np.abs(information[-1] - information[-2]).max() < 1e-9 * scale

    one_frame = crlb(model, slew, pitches, 0.1)
    still = (np.full(frames, slew), np.tile(pitches, (frames, 1)))
    steady = {q: posterior_crlb(model, *still, 0.1, dt, q)[-1] for q in (1e-4, 1e-2, 1.0, 1e8)}
    assert steady[1e-4].rmse < steady[1e-2].rmse < steady[1.0].rmse < one_frame.rmse
    assert steady[1e-4].rmse < 0.5 * one_frame.rmse
    assert steady[1e8].rmse == pytest.approx(one_frame.rmse, rel=1e-6)
    assert np.all(np.diag(steady[1e-2].parameter_covariance)
                  < np.diag(one_frame.parameter_covariance))


def test_boom_bound_tends_to_single_frame_bound_as_noise_grows():
    model = truck_pump()
    trajectory = working_cycle(model, 10.0, 10.0)
    bounds = posterior_crlb(model, trajectory.slew, trajectory.pitches, 0.1, 0.1, 1e8)
    for k, bound in enumerate(bounds):
        single = crlb(model, trajectory.slew[k], trajectory.pitches[k], 0.1)
        assert bound.rmse == pytest.approx(single.rmse, rel=1e-6)
        scale = np.abs(single.parameter_covariance).max()
        np.testing.assert_allclose(bound.parameter_covariance, single.parameter_covariance,
                                   rtol=1e-6, atol=1e-6 * scale)
        np.testing.assert_allclose(bound.joint_covariance, single.joint_covariance,
                                   rtol=1e-5, atol=1e-6 * np.abs(single.joint_covariance).max())


def test_boom_bound_with_a_smooth_motion_is_well_below_single_frames():
    model = truck_pump()
    trajectory = working_cycle(model, 20.0, 10.0)
    sigma = np.full((model.n_sections, model.n_anchors), 0.1)
    bounds = posterior_crlb(model, trajectory.slew, trajectory.pitches, sigma, 0.1,
                            np.full(model.n_sections + 1, 1e-4))
    posterior = np.array([bound.rmse for bound in bounds])
    single = np.array([crlb(model, s, p, sigma).rmse
                       for s, p in zip(trajectory.slew, trajectory.pitches)])
    # Without a prior, two frames cannot fix the rates: the first two are single-frame bounds.
    np.testing.assert_allclose(posterior[:2], single[:2], rtol=1e-9)
    assert np.all(posterior <= single * (1 + 1e-9))
    assert np.all(posterior[50:] < 0.6 * single[50:])
    # A prior helps from the first frame on.
    prior = np.diag(np.r_[np.full(model.n_sections + 1, 1e6), np.full(model.n_sections + 1, 1e2)])
    first = posterior_crlb(model, trajectory.slew[:1], trajectory.pitches[:1], sigma, 0.1, 1e-4,
                           initial_information=prior)[0]
    assert first.rmse < single[0]


def test_motion_model_carries_a_frame_with_too_few_links():
    model = truck_pump()
    trajectory = working_cycle(model, 3.0, 10.0)
    frames, p, m = trajectory.slew.size, model.n_sections, model.n_anchors
    measured = np.ones((frames, p, m), bool)
    measured[20] = False
    measured[20, :, 1] = True                               # p ranges for p + 1 angles
    bounds = posterior_crlb(model, trajectory.slew, trajectory.pitches, 0.1, 0.1, 1e-2,
                            measured)
    assert crlb(model, trajectory.slew[20], trajectory.pitches[20], 0.1, measured[20]).rmse \
        == np.inf
    assert np.isfinite(bounds[20].rmse)
    assert bounds[19].rmse < bounds[20].rmse < 10 * bounds[19].rmse
    assert bounds[21].rmse < bounds[20].rmse
    # The same frame first, with nothing before it, stays undetermined.
    alone = posterior_crlb(model, trajectory.slew[20:22], trajectory.pitches[20:22], 0.1, 0.1,
                           1e-2, measured[20:22])
    assert alone[0].rmse == np.inf
    assert np.all(alone[0].joint_covariance == np.inf)
    assert np.isfinite(alone[1].rmse)


@pytest.mark.parametrize('change, field', [
    ({'slew': np.zeros((4, 1))}, 'slew'),
    ({'pitches': np.zeros((4, 4))}, 'pitches'),
    ({'pitches': np.zeros((3, 5))}, 'pitches'),
    ({'frame_period': 0.0}, 'frame_period'),
    ({'frame_period': -0.1}, 'frame_period'),
    ({'frame_period': np.nan}, 'frame_period'),
    ({'process_noise': -1e-3}, 'process_noise'),
    ({'process_noise': np.r_[1.0, 1.0, -1.0, 1.0, 1.0, 1.0]}, 'process_noise'),
    ({'process_noise': np.ones(5)}, 'process_noise'),
    ({'measured': np.ones((5, 5), bool)}, 'measured'),
    ({'measured': np.ones((3, 5, 6), bool)}, 'measured'),
    ({'initial_information': np.eye(6)}, 'initial_information'),
    ({'initial_information': -np.eye(12)}, 'initial_information'),
])
def test_posterior_crlb_rejects_bad_inputs(change, field):
    model = truck_pump()
    arguments = {'slew': np.zeros(4), 'pitches': np.full((4, 5), 0.3), 'frame_period': 0.1,
                 'process_noise': 1e-2, 'measured': None, 'initial_information': None}
    arguments.update(change)
    with pytest.raises(ValueError, match=field):
        posterior_crlb(model, arguments['slew'], arguments['pitches'], 0.1,
                       arguments['frame_period'], arguments['process_noise'],
                       arguments['measured'], arguments['initial_information'])


@pytest.mark.parametrize('change, field', [
    ({'transition': np.eye(2)[:1]}, 'transition'),
    ({'transition': np.array([[1.0, 1.0], [1.0, 1.0]])}, 'transition'),
    ({'process_covariance': np.eye(3)}, 'process_covariance'),
    ({'process_covariance': np.array([[1.0, 0.5], [0.0, 1.0]])}, 'process_covariance'),
    ({'process_covariance': -np.eye(2)}, 'process_covariance'),
    ({'measurement_information': np.eye(2)}, 'measurement_information'),
    ({'measurement_information': np.full((3, 2, 2), np.nan)}, 'measurement_information'),
    ({'measurement_information': -np.ones((1, 2, 2))}, 'measurement_information'),
    ({'initial_information': np.zeros((2, 3))}, 'initial_information'),
])
def test_posterior_information_rejects_bad_inputs(change, field):
    arguments = {'transition': np.eye(2), 'process_covariance': np.eye(2),
                 'measurement_information': np.ones((3, 2, 2)),
                 'initial_information': np.zeros((2, 2))}
    arguments.update(change)
    with pytest.raises(ValueError, match=field):
        posterior_information(**arguments)


@pytest.mark.parametrize('link_std, common_std', [(0.1, 0.0), (0.0, 0.3), (0.05, 0.2)])
def test_range_biases_add_the_covariance_they_give_a_weighted_fit(link_std, common_std):
    # Fit psi by weighted least squares to ranges with biases constant per link plus
    # noise; the spread of the estimates is F^-1 plus the biases' part (a linearisation:
    # biases of tenths of a metre over ranges of ~20 m).
    model = truck_pump()
    truth = np.r_[0.4, np.radians([50.0, 25.0, 5.0, -20.0, -45.0])]
    rng = np.random.default_rng(31)
    sigma, trials = 0.05, 400
    distances = model.ranges(model.forward_kinematics(truth[0], truth[1:]))
    estimates = []
    for _ in range(trials):
        bias = common_std * rng.standard_normal() + link_std * rng.standard_normal(
            distances.shape)
        frame = Measurements.ranges_only(distances + bias
                                         + sigma * rng.standard_normal(distances.shape))
        residuals = Residuals(model, frame, SensorNoise(sigma))
        estimates.append(least_squares(lambda psi: residuals.residuals(psi)[0], truth,
                                       jac=residuals.jacobian, method='lm', xtol=1e-12).x)
    residuals = Residuals(model, Measurements.ranges_only(distances), SensorNoise(sigma))
    jacobian = residuals.jacobian(truth)
    inverse = np.linalg.inv(jacobian.T @ jacobian)
    common = (np.ones((residuals.size, 1)), np.array([[common_std ** 2]]))
    expected = inverse + bias_covariance(jacobian, residuals.sigma, residuals.ranged(),
                                         inverse, link_std, common)
    measured = np.cov(np.array(estimates).T)
    # Variances of 400 draws: relative standard error sqrt(2 / 400) = 7 %.
    np.testing.assert_allclose(np.diag(measured), np.diag(expected),
                               rtol=5 * np.sqrt(2 / trials))


def test_a_poorly_controlled_link_adds_what_leaving_it_out_would():
    """Each link the others barely check widens the bound to its leave-one-out bound."""
    rng = np.random.default_rng(4)
    jacobian = rng.standard_normal((12, 3))
    jacobian[11] *= 30.0        # one link carries most of what the frame knows
    information_inverse = np.linalg.inv(jacobian.T @ jacobian)
    hat = np.einsum('iq,qr,ir->i', jacobian, information_inverse, jacobian)
    assert hat[11] > 1.0 - POORLY_CONTROLLED and np.all(hat[:11] < 1.0 - POORLY_CONTROLLED)
    added = uncontrolled_covariance(jacobian, information_inverse)
    without = np.linalg.inv(jacobian[:11].T @ jacobian[:11])
    np.testing.assert_allclose(information_inverse + added, without, rtol=1e-9)
    # Links all checked by the others add nothing; at a floor of 1 every one counts.
    np.testing.assert_array_equal(uncontrolled_covariance(jacobian[:11], without), 0.0)
    every = uncontrolled_covariance(jacobian, information_inverse, floor=1.0)
    expected = sum(np.linalg.inv(np.delete(jacobian, i, axis=0).T
                                 @ np.delete(jacobian, i, axis=0)) - information_inverse
                   for i in range(12))
    np.testing.assert_allclose(every, expected, rtol=1e-9, atol=1e-15)


def test_range_bias_prior_validates():
    assert not RangeBiasPrior() and RangeBiasPrior(0.0, 0.1)
    for value in (-0.1, np.nan, np.inf, 'x', True, None, [[0.1, -0.1]], [[np.nan]]):
        with pytest.raises(ValueError, match='^link_std'):
            RangeBiasPrior(link_std=value)
    # One per link: kept as a read-only array; known to be zero everywhere is no bias.
    per_link = RangeBiasPrior(link_std=[[0.0, 0.1], [0.2, 0.0]])
    assert per_link and not per_link.link_std.flags.writeable
    assert not RangeBiasPrior(link_std=np.zeros((2, 2)))


def section_directions(slew, pitches):
    """Return unit vectors (..., p, 3) along each section at slews (...), pitches (..., p)."""
    slew = np.asarray(slew)[..., None]
    return np.stack([np.cos(pitches) * np.cos(slew), np.cos(pitches) * np.sin(slew),
                     np.sin(pitches)], axis=-1)


def test_a_sections_direction_std_is_the_rms_turn_of_postures_drawn_from_the_bound():
    model = truck_pump()
    slew, pitches = 0.4, np.radians([60.0, 30.0, 0.0, -30.0, -80.0])
    bound = crlb(model, slew, pitches, 0.3)
    trials = 4000
    drawn = np.random.default_rng(7).multivariate_normal(
        np.r_[slew, pitches], bound.parameter_covariance, trials)
    now = section_directions(drawn[:, 0], drawn[:, 1:])
    then = section_directions(slew, pitches)
    turned = np.arctan2(np.linalg.norm(np.cross(now, then), axis=-1), np.sum(now * then, -1))
    # A mean of squares of 4000 draws: relative standard error at most sqrt(2 / 4000).
    np.testing.assert_allclose(np.sqrt(np.mean(turned ** 2, axis=0)),
                               bound.direction_std(pitches), rtol=5 * np.sqrt(2 / trials) / 2)
    unmeasured = crlb(model, slew, np.radians([90.0, 0, 0, 0, 0]), 0.3,
                      np.zeros((model.n_sections, model.n_anchors), dtype=bool))
    assert np.all(unmeasured.direction_std(np.radians([90.0, 0, 0, 0, 0])) == np.inf)


def test_a_covariance_its_rounding_swamps_gives_an_infinite_bound_never_nan():
    """
    1e19 rad^2 along a direction that leaves the tip where it is, beside 1e-4 elsewhere.

    The tip's variance is then lost in the rounding of the rest (it came out negative on
    about half these postures, and its std NaN: a field frame with a tag silent and
    another on two links did so, session 36): such a bound says nothing, infinite.
    """
    model = truck_pump()
    p = model.n_sections
    rng = np.random.default_rng(0)
    unbounded = 0
    for _ in range(50):
        slew, pitches, _ = random_posture(model, rng)
        still = np.linalg.svd(model.joint_jacobian(slew, pitches)[-1])[2][-1]
        covariance = 1e-4 * np.eye(p + 1) + 1e19 * np.outer(still, still)
        bound = bound_from_covariance(model, slew, pitches, covariance)
        assert not np.isnan(bound.joint_std).any() and not np.isnan(bound.rmse)
        if np.isinf(bound.rmse):
            assert np.all(np.isinf(bound.joint_std))
            unbounded += 1
        else:
            assert np.all(bound.joint_std >= 0.0)
    assert unbounded > 0                # the rounding did swamp the tip on some
