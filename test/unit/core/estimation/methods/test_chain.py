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

"""The chain estimator and the Cramér–Rao bound."""
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.methods.chain import angles_from_joints, ChainMethod
from epp_ros.core.model.bounds import crlb, fisher_information
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation.simulate import (random_posture, RangeNoise, truck_pump,
                                              working_cycle, xie3dim)
from monte_carlo import assert_mse_at_bound, UNBIASED
import numpy as np
import pytest

GEOMETRIES = {'xie3dim': lambda: xie3dim()[0], 'truck': truck_pump}


@pytest.mark.parametrize('geometry', sorted(GEOMETRIES))
def test_cold_start_recovers_any_posture_exactly(geometry):
    model = GEOMETRIES[geometry]()
    rng = np.random.default_rng(1)
    for _ in range(15):
        slew, pitches, joints = random_posture(model, rng)
        estimator = PostureEstimator(model, 'chain', sigma=1e-3, nlos_fraction=0.0, **UNBIASED)
        np.testing.assert_allclose(estimator.update(model.ranges(joints)), joints, atol=1e-8)
        diagnostics = estimator.last_diagnostics
        assert diagnostics['status'] == 'ok' and not diagnostics['nlos_links'].any()
        assert np.angle(np.exp(1j * (diagnostics['slew'] - slew))) == pytest.approx(0, abs=1e-8)


def test_warm_start_tracks_exactly_and_lengths_hold_by_construction():
    model = truck_pump()
    trajectory = working_cycle(model, 10.0, 10.0, rng=np.random.default_rng(2))
    estimator = PostureEstimator(model, 'chain')
    # The fit stops once a step is under 1e-10 rad; Gauss-Newton on exact ranges leaves
    # far less than a step's motion at the tip's lever (sum of lengths): 100 steps' worth
    # is a bound no rounding reaches (seen: 7e-10 m and 8e-12 m on two BLAS kernels).
    atol = 100 * 1e-10 * model.arm_lengths.sum()
    for joints in trajectory.joints:
        np.testing.assert_allclose(estimator.update(model.ranges(joints)), joints, atol=atol)
    noisy = estimator.update(RangeNoise(sigma=1.0).apply(
        model.ranges(trajectory.joints[-1]), np.random.default_rng(3))[0])
    np.testing.assert_allclose(model.section_lengths(noisy), model.arm_lengths, atol=1e-9)


def test_fisher_information_matches_finite_differences():
    model = xie3dim()[0]
    slew, pitches, _ = random_posture(model, np.random.default_rng(4))
    psi = np.r_[slew, pitches]
    sigma = np.random.default_rng(5).uniform(0.1, 1.0, (model.n_sections, model.n_anchors))
    measured = np.random.default_rng(6).random(sigma.shape) > 0.2

    def ranges(angles):
        return model.ranges(model.forward_kinematics(angles[0], angles[1:]))

    step = 1e-6
    columns = [(ranges(psi + step * e) - ranges(psi - step * e)) / (2 * step)
               for e in np.eye(psi.size)]
    jacobian = np.stack(columns, axis=-1)[measured] / sigma[measured][:, None]
    np.testing.assert_allclose(fisher_information(model, slew, pitches, sigma, measured),
                               jacobian.T @ jacobian, rtol=1e-6, atol=1e-8)


def test_bound_of_the_authors_geometry_is_the_published_one():
    """Method notes: on xie3dim at sigma = 1 m the chain bound is near 1.0 m."""
    model, joints = xie3dim()
    slew, pitches = angles_from_joints(model, joints)
    bound = crlb(model, slew, pitches, 1.0)
    assert 0.95 < bound.rmse < 1.08
    assert bound.joint_std.shape == (5,) and np.all(bound.joint_std > 0)
    # Fewer links: a larger bound; too few: an infinite one.
    measured = np.ones((5, 4), bool)
    measured[:, 3] = False
    assert crlb(model, slew, pitches, 1.0, measured).rmse > bound.rmse
    assert crlb(model, slew, pitches, 1.0, np.zeros((5, 4), bool)).rmse == np.inf


def test_monte_carlo_rmse_matches_the_bound():
    """Small noise: the estimator is efficient. The tolerance follows from the trial count."""
    model = truck_pump()
    rng = np.random.default_rng(7)
    slew, pitches, joints = random_posture(model, rng)
    sigma, trials = 0.05, 400
    bound = crlb(model, slew, pitches, sigma)
    estimator = PostureEstimator(model, 'chain', sigma=sigma, **UNBIASED)
    estimator.update(model.ranges(joints))                      # warm start at the truth
    squared = []
    for _ in range(trials):
        estimate = estimator.update(RangeNoise(sigma=sigma).apply(model.ranges(joints),
                                                                  rng)[0])
        squared.append(np.sum((estimate - joints) ** 2) / model.n_sections)
    assert_mse_at_bound(squared, bound.rmse, estimator)


def test_nlos_links_are_flagged_and_do_not_pull_the_estimate():
    model = truck_pump()
    rng = np.random.default_rng(8)
    joints = random_posture(model, rng)[2]
    ranges, _ = RangeNoise(sigma=0.05).apply(model.ranges(joints), rng)
    blocked = [(4, 1), (3, 2), (2, 5)]
    for k, j in blocked:
        ranges[k, j] += 3.0                                      # a detour around the boom
    robust = PostureEstimator(model, 'chain', sigma=0.05)
    plain = PostureEstimator(model, 'chain', sigma=0.05, nlos_fraction=0.0)
    estimate, naive = robust.update(ranges), plain.update(ranges)
    flagged = robust.last_diagnostics['nlos_links']
    assert {tuple(i) for i in np.argwhere(flagged)} == set(blocked)
    robust_error = np.sqrt(np.mean(np.sum((estimate - joints) ** 2, axis=1)))
    plain_error = np.sqrt(np.mean(np.sum((naive - joints) ** 2, axis=1)))
    slew, pitches = robust.last_diagnostics['slew'], robust.last_diagnostics['pitches']
    bound = crlb(model, slew, pitches, 0.05, ~flagged).rmse       # LOS links alone
    assert robust_error < 4 * bound < plain_error


def test_needs_the_tip_and_enough_links():
    model = truck_pump()
    joints = random_posture(model, np.random.default_rng(9))[2]
    ranges = model.ranges(joints)
    ranges[-1] = np.nan                                          # the tip unheard
    estimator = PostureEstimator(model, 'chain')
    assert np.all(np.isfinite(estimator.update(ranges)))
    assert estimator.last_diagnostics['status'] == 'insufficient_data'
    sparse = np.full_like(ranges, np.nan)
    sparse[:, 1] = model.ranges(joints)[:, 1]
    sparse[4, 2] = model.ranges(joints)[4, 2]                    # p + 1 = 6 links
    estimator.update(sparse)
    # Six links do not single out the posture: the fit explains them exactly, and is
    # reported as not determined rather than published.
    diagnostics = estimator.last_diagnostics
    estimate = diagnostics['estimate']
    assert diagnostics['status'] in ('ambiguous', 'unobservable') and not diagnostics['valid']
    assert diagnostics['range_residual_rms'] < 1e-6
    np.testing.assert_allclose(model.section_lengths(estimate), model.arm_lengths)


def test_joints_are_held_above_lowest_joint():
    model = truck_pump()
    rng = np.random.default_rng(12)
    while True:
        slew, pitches, joints = random_posture(model, rng)
        if joints[:, 2].min() < 2.0:
            break
    ranges = model.ranges(joints)
    free = PostureEstimator(model, 'chain', lowest_joint=-100.0)
    np.testing.assert_allclose(free.update(ranges), joints, atol=1e-8)
    floor = joints[:, 2].min() + 1.0                 # the true posture dips below it
    estimator = PostureEstimator(model, 'chain', lowest_joint=floor)
    estimator.update(ranges)
    held = estimator.last_diagnostics['estimate']
    assert held[:, 2].min() > floor - 0.2
    np.testing.assert_allclose(model.section_lengths(held), model.arm_lengths)


def test_a_search_over_budget_leaves_the_frame_unsolved_and_goes_on_next_frame():
    """Garbage must not stall the node: a search stops at its budget and resumes."""
    model = truck_pump()
    joints = random_posture(model, np.random.default_rng(20))[2]
    estimator = PostureEstimator(model, 'chain', search_budget=60, sigma=1e-3,
                                 nlos_fraction=0.0)
    statuses = []
    for frame in range(12):
        estimate = estimator.update(model.ranges(joints), stamp=0.1 * frame)
        diagnostics = estimator.last_diagnostics
        statuses.append(diagnostics['status'])
        if diagnostics['valid']:
            break
    assert statuses[0] == 'solver_failed'
    assert 'budget' in estimator.last_diagnostics.get('error', '') or statuses[-1] == 'ok'
    assert statuses[-1] == 'ok' and len(statuses) > 1      # resumed, then found
    np.testing.assert_allclose(estimate, joints, atol=1e-6)
    with pytest.raises(ValueError, match='search_budget'):
        PostureEstimator(model, 'chain', search_budget=0)


def test_fits_side_by_side_on_some_links_are_the_one_loops_fits():
    """
    Each subset's batch fit ends where the single loop's does, at no higher a cost.

    The single loop stops when a step gains less than 1e-6 of the cost; in a flat valley
    the batch, given its rounds, goes on a few centimetres further down it.
    """
    model = truck_pump()
    method = ChainMethod(model, nlos_fraction=0.1, nlos_gamma=1.0)
    rng = np.random.default_rng(7)
    p, m = model.n_sections, model.n_anchors
    for _ in range(5):
        _, _, joints = random_posture(model, rng)
        sigma = rng.uniform(0.05, 0.2, (p, m))
        ranges = model.ranges(joints) + rng.normal(0.0, sigma)
        blocked = rng.random((p, m)) < 0.15
        ranges[blocked] += rng.exponential(1.0, blocked.sum())
        ranges[rng.random((p, m)) < 0.1] = np.nan
        masks = np.ones((p + 1, p, m), dtype=bool)
        masks[np.arange(p), np.arange(p)] = False           # each tag left out, then none
        start = joints + rng.normal(0.0, 0.3, joints.shape)
        batch = method.refine_links(start, ranges, sigma, masks, rounds=200)
        noise = SensorNoise(sigma, 0.1, 0.01, 0.01)
        for mask, fitted in zip(masks, batch):
            frame = Measurements.ranges_only(np.where(mask, ranges, np.nan))
            residuals = Residuals(model, frame, noise)
            single, fit = method.refine(start, residuals, max_iter=200)
            batch_cost = method.cost(np.r_[angles_from_joints(model, fitted)], residuals)
            assert batch_cost <= fit.cost * (1 + 1e-6)      # the single loop's stall
            np.testing.assert_allclose(fitted, single, atol=0.05)


def test_a_postures_angles_asked_for_again_are_the_same_and_the_callers_own():
    """A frame's judgement, its publication and the next frame's start share them, per boom."""
    model = truck_pump()
    psi = np.r_[0.4, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])]
    joints = model.forward_kinematics(psi[0], psi[1:])
    slew, pitches = angles_from_joints(model, joints)
    pitches[:] = 0.0                                 # the caller's copy
    again = angles_from_joints(model, joints.tolist())
    assert again[0] == slew
    np.testing.assert_allclose(again[1], psi[1:], atol=1e-9)
    higher = truck_pump(base_height=model.base[2] + 1.0)     # the same joints, another base
    assert abs(angles_from_joints(higher, joints)[1][0] - psi[1]) > 0.01
    assert abs(angles_from_joints(model, joints + [0.0, 0.0, 0.5])[1][0] - psi[1]) > 0.01
