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

"""The NLOS range error model, and the chain's global search under it."""
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.methods.chain import ChainMethod
from epp_ros.core.model.measurements import Measurements, Residuals
from epp_ros.core.model.nlos import (BOUND_SIZE, LinkLoss, NlosMixture, OUTLIER_FRACTION,
                                     OUTLIER_SIGMA, OUTLIER_SPREAD, range_excess)
from epp_ros.core.simulation.simulate import observe, random_posture, RangeNoise, truck_pump
import numpy as np
import pytest
from scipy.stats import exponnorm, norm

SIGMA, FRACTION, GAMMA = 0.2, 0.2, 2.0


def mixture_densities(error, sigma, fraction, gamma, outliers=0.0):
    """Prior-weighted densities (line of sight, blocked, outlier) of range errors, metres."""
    return ((1 - fraction - outliers) * norm.pdf(error, scale=sigma),
            fraction * exponnorm.pdf(error, gamma / sigma, scale=sigma),
            outliers * norm.pdf(error, scale=np.hypot(OUTLIER_SIGMA, OUTLIER_SPREAD * sigma)))


def mixture_nll(excess, sigma, fraction, gamma, outliers=0.0):
    """Negative log-density of ``excess * sigma`` from scipy's own distributions."""
    return -np.log(sum(mixture_densities(excess * sigma, sigma, fraction, gamma, outliers)))


@pytest.mark.parametrize('outliers', [0.0, OUTLIER_FRACTION])
def test_loss_is_the_mixture_likelihood_up_to_a_line(outliers):
    model = NlosMixture(FRACTION, GAMMA, outliers)
    excess = np.linspace(-6.0, 60.0, 2001)
    cost, slope, _ = model.loss(excess, SIGMA)
    reference = mixture_nll(excess, SIGMA, FRACTION, GAMMA, outliers)
    # Second differences cancel the constant and the linear shift.
    np.testing.assert_allclose(np.diff(cost, 2), np.diff(reference, 2), atol=1e-9)
    np.testing.assert_allclose(np.gradient(cost, excess)[1:-1], slope[1:-1], atol=2e-3)
    zero_cost, zero_slope, _ = model.loss(np.zeros(1), SIGMA)
    assert zero_cost == pytest.approx([0.0], abs=1e-15)
    assert zero_slope == pytest.approx([0.0], abs=1e-15)


def test_posterior_is_bayes_rule_and_the_pull_of_a_blocked_link_is_bounded():
    model = NlosMixture(FRACTION, GAMMA).judged()
    excess = np.array([-3.0, 0.0, 1.0, 3.0, 10.0, 50.0])
    _, slope, nlos = model.loss(excess, SIGMA)
    los, blocked, outlier = mixture_densities(excess * SIGMA, SIGMA, FRACTION, GAMMA,
                                              OUTLIER_FRACTION)
    total = los + blocked + outlier
    np.testing.assert_allclose(nlos, blocked / total, rtol=1e-9)
    loss = model.bind(np.full(excess.shape, SIGMA))
    np.testing.assert_allclose(loss.posteriors(excess)[0], nlos, rtol=1e-12)
    np.testing.assert_allclose(loss.posteriors(excess)[1], outlier / total, rtol=1e-9)
    assert nlos[0] < 0.01 and nlos[-1] > 0.99       # 10 m long: an outlier, hardly
    assert 0 < slope[-1] < 2 * SIGMA / GAMMA       # a least-squares link would pull by 50


def test_the_share_off_the_line_of_sight_is_the_priors_mean_plus_the_outliers():
    """``LinkLoss.off_line``: how many links a fit may set aside by chance."""
    sigma = np.full(4, SIGMA)
    judged = NlosMixture(FRACTION, GAMMA).judged(0.02)
    assert judged.bind(sigma).off_line == pytest.approx(FRACTION + 0.02)
    prior = np.array([0.05, 0.1, 0.2, 0.25])
    assert LinkLoss(judged, sigma, prior).off_line == pytest.approx(0.15 + 0.02)
    assert NlosMixture(0.0, GAMMA).bind(sigma).off_line == 0.0       # least squares


def test_a_short_range_far_outside_the_noise_is_an_outlier_of_bounded_pull():
    """Real links have outliers of either sign: a range 3 m short moves a fit little."""
    model = NlosMixture(FRACTION, GAMMA).judged()
    assert model.outliers == OUTLIER_FRACTION and model.judged() is model
    excess = np.array([-0.5, -2.0, -30.0, -3.0 / SIGMA, 3.0 / SIGMA])
    cost, slope, nlos = model.loss(excess, SIGMA)
    _, outlier = model.bind(np.full(excess.shape, SIGMA)).posteriors(excess)
    assert outlier[0] < 1e-3 and outlier[1] < 0.05        # within the noise: line of sight
    assert outlier[3] > 0.99 and nlos[3] < 1e-9
    assert outlier[4] < 0.5 < nlos[4]                     # as long: blocked, far likelier
    # Least squares would pull by 15 sigma and cost 112: the outlier's Gaussian by ~0.15.
    assert abs(slope[3]) < 0.2 and cost[3] < 15.0
    assert abs(slope[2]) < abs(slope[3]) * 15.0           # and the pull falls off slowly


def test_no_nlos_is_least_squares_and_bad_parameters_are_refused():
    excess = np.linspace(-5, 5, 11)
    cost, slope, nlos = NlosMixture(0.0, 1.0).loss(excess, 0.1)
    np.testing.assert_array_equal(cost, 0.5 * excess ** 2)
    np.testing.assert_array_equal(slope, excess)
    assert not nlos.any()
    for fraction, gamma in ((1.0, 1.0), (-0.1, 1.0), (0.1, 0.0), (0.1, np.nan)):
        with pytest.raises(ValueError, match='nlos_'):
            NlosMixture(fraction, gamma)
    for outliers, outlier_sigma in ((-0.1, 1.0), (0.9, 1.0), (0.01, 0.0)):
        with pytest.raises(ValueError, match='outlier'):
            NlosMixture(0.1, 1.0, outliers, outlier_sigma)


def test_outliers_without_nlos_are_the_two_gaussians():
    model = NlosMixture(0.0, 1.0, OUTLIER_FRACTION)
    excess = np.linspace(-40.0, 40.0, 801)
    cost, slope, nlos = model.loss(excess, SIGMA)
    reference = mixture_nll(excess, SIGMA, 0.0, 1.0, OUTLIER_FRACTION)
    np.testing.assert_allclose(np.diff(cost, 2), np.diff(reference, 2), atol=1e-9)
    assert NlosMixture(0.0).judged().gaussian and NlosMixture(0.1).outliers == 0.0
    step = 1e-6
    central = (model.loss(excess + step, SIGMA)[0] - model.loss(excess - step, SIGMA)[0])
    np.testing.assert_allclose(central / (2 * step), slope, atol=1e-6)
    assert not nlos.any() and np.all(np.isfinite(cost))


@pytest.mark.parametrize('sigma', [0.05, 0.2, 1.0])
def test_approximate_loss_stays_within_log_three_of_the_loss(sigma):
    model = NlosMixture(0.1, 1.0).judged()
    excess = np.linspace(-10.0 / sigma, 100.0, 5001)
    # The likelihood per unit of excess, without the loss's constant and tilt.
    exact = (mixture_nll(excess, sigma, model.fraction, model.gamma, model.outliers)
             - np.log(np.sqrt(2 * np.pi) * sigma) + np.log1p(-model.fraction - model.outliers))
    gap = exact - model.approximate_loss(excess, sigma)
    assert np.all(gap <= 1e-9) and np.all(gap >= -np.log(3.0) - 1e-9)


def test_a_frames_sigmas_are_bound_once_and_the_kept_loss_is_a_fresh_ones():
    """Fits and checks bind the same few dozen sigmas many times: one bound loss serves."""
    mixture = NlosMixture(0.1, 1.0).judged()
    sigma = np.hypot(0.1, 0.01 * np.arange(30.0)).reshape(5, 6)
    bound = mixture.bind(sigma)
    assert mixture.bind(sigma.copy()) is bound
    assert mixture.bind(sigma + 1e-9) is not bound
    assert NlosMixture(0.1, 1.0).bind(sigma) is not bound
    excess = np.random.default_rng(4).normal(0.0, 3.0, sigma.shape)
    for kept, fresh in zip(bound(excess), LinkLoss(mixture, sigma)(excess)):
        np.testing.assert_array_equal(kept, fresh)
    prior = np.full(sigma.shape, 0.3)           # a link's own prior: bound each time
    assert mixture.bind(sigma, prior) is not mixture.bind(sigma, prior)
    large = np.full(BOUND_SIZE + 1, 0.1)        # a calibration's frames: not kept
    assert mixture.bind(large) is not mixture.bind(large)


def test_range_excess_is_in_sigmas_per_tag_and_zero_where_unheard():
    anchors = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    ranges = np.array([[5.5, np.nan, 4.0], [1.0, 2.0, np.nan]])
    sigma = np.array([[0.5, 0.5, 2.0], [0.1, 0.2, 0.1]])
    points = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])     # one per tag
    expected = np.array([[0.5 / 0.5, 0.0, (4.0 - 3.0) / 2.0],
                         [0.0, (2.0 - np.sqrt(10.0)) / 0.2, 0.0]])
    np.testing.assert_allclose(range_excess(points, anchors, ranges, sigma), expected)
    # One tag at many candidates; the loss of a missing range is nothing.
    candidates = np.stack([points[0], points[0] + [0.0, 0.0, 12.0]])
    one_tag = range_excess(candidates, anchors, ranges[0], sigma[0])
    assert one_tag.shape == (2, 3) and np.all(one_tag[:, 1] == 0.0)
    np.testing.assert_allclose(one_tag[0], expected[0])
    np.testing.assert_allclose(one_tag[1, 0], (5.5 - 13.0) / 0.5)
    assert NlosMixture(FRACTION, GAMMA).loss(one_tag, sigma[0])[0][:, 1].tolist() == [0.0, 0.0]


def test_cold_start_finds_the_global_fit_with_blocked_links():
    """No fit started at the true posture ends lower than the cold start's."""
    model = truck_pump()
    rng = np.random.default_rng(11)
    noise = RangeNoise(sigma=SIGMA, nlos_fraction=FRACTION, nlos_gamma=GAMMA)
    recall = []
    for _ in range(12):
        slew, pitches, _ = random_posture(model, rng)
        frame, blocked = observe(model, slew, pitches, rng, noise)
        measurements = Measurements.ranges_only(frame['ranges'])
        chain = ChainMethod(model, sigma=SIGMA, nlos_fraction=FRACTION, nlos_gamma=GAMMA)
        residuals = Residuals(model, measurements, chain.noise)
        estimator = PostureEstimator(model, 'chain', sigma=SIGMA, nlos_fraction=FRACTION,
                                     nlos_gamma=GAMMA)
        estimator.update(frame['ranges'])
        info = estimator.last_diagnostics
        # Both the judge's cost (``ChainMethod.fit``'s).
        found = chain.cost(np.r_[info['slew'], info['pitches']], residuals)
        from_truth = chain.fit(np.r_[slew, pitches], residuals)[1]
        assert found <= from_truth * (1 + 1e-6)          # the fits' stall
        flagged = info['nlos_links']
        recall.append((flagged & blocked).sum() / max(blocked.sum(), 1))
        assert (flagged & ~blocked).sum() <= 1       # LOS links are rarely taken for NLOS
    assert np.mean(recall) > 0.5


@pytest.mark.parametrize('fraction, gamma, share', [(0.05, 1.0, 0.005), (0.3, 0.3, 0.05),
                                                    (0.6, 2.5, 0.2), (0.0, 1.0, 0.01)])
def test_no_excess_costs_a_link_less_than_its_floor(fraction, gamma, share):
    """
    The floor bounds the tilted loss from below, learned shares and all.

    Within a few hundredths of a nat where one term of the mixture rules: the line of
    sight's at the loss's own default shares.
    """
    rng = np.random.default_rng(7)
    sigma = rng.uniform(0.02, 0.5, (3, 4))
    excess = np.linspace(-40.0, 40.0, 16001)[:, None, None]
    for prior in (None, rng.uniform(0.0, 0.9, (3, 4))):
        loss = LinkLoss(NlosMixture(fraction, gamma).judged(share), sigma, prior)
        least = loss(np.broadcast_to(excess, excess.shape[:1] + sigma.shape))[0].min(axis=0)
        assert loss.floor.shape == sigma.shape and np.all(loss.floor <= least)
        if fraction <= 0.05 and prior is None:
            assert np.all(loss.floor >= least - 0.05)
    gaussian = LinkLoss(NlosMixture(0.0, 1.0), sigma)
    assert np.all(gaussian.floor == 0.0) and gaussian.floor.shape == sigma.shape
