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

"""The range noise learned from residuals: known answers, and through the estimator."""
from epp_ros.app.health import report
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.noise_learning import frame_scale, NoiseLearner, RangeNoiseEstimate
from epp_ros.core.model.bounds import crlb
from epp_ros.core.model.nlos import OUTLIER_FRACTION
from epp_ros.core.simulation.simulate import truck_pump, xie3dim
import numpy as np
import pytest

CONFIGURED = RangeNoiseEstimate(0.1, 0.0, 0.1, 1.0)
LINKS_PER_FRAME = 30


def learn(sigma, eta=0.0, fraction=0.0, gamma=1.0, frames=200, seed=0, configured=CONFIGURED,
          outliers=0.0, outlier_size=3.0):
    """Feed a learner ``frames`` frames of exact-model residuals; return it and the count."""
    rng = np.random.default_rng(seed)
    learner = NoiseLearner(configured)
    for _ in range(frames):
        distances = rng.uniform(5.0, 35.0, LINKS_PER_FRAME)
        excess = np.hypot(sigma, eta * distances) * rng.standard_normal(LINKS_PER_FRAME)
        blocked = rng.random(LINKS_PER_FRAME) < fraction
        excess = excess + blocked * rng.exponential(gamma, LINKS_PER_FRAME)
        outlying = rng.random(LINKS_PER_FRAME) < outliers
        excess = np.where(outlying, rng.normal(0.0, outlier_size, LINKS_PER_FRAME), excess)
        learner.observe(excess, distances, 0)
    return learner, learner.window * LINKS_PER_FRAME


@pytest.mark.parametrize('sigma', [0.01, 0.3, 1.0])
def test_sigma_is_learned_whatever_was_configured(sigma):
    learner, links = learn(sigma)
    # A sample standard deviation of n draws has relative standard error 1 / sqrt(2 n);
    # the robust start and the EM weights cost some efficiency: 5 errors, doubled.
    assert learner.settled
    assert learner.estimate.sigma == pytest.approx(sigma, rel=10 / np.sqrt(2 * links))
    assert learner.estimate.nlos_fraction < 0.03


def test_nlos_fraction_and_excess_are_learned():
    fraction, gamma = 0.2, 1.0
    learner, links = learn(0.1, fraction=fraction, gamma=gamma)
    estimate = learner.estimate
    blocked = fraction * links
    assert estimate.sigma == pytest.approx(0.1, rel=10 / np.sqrt(2 * (links - blocked)))
    assert estimate.nlos_fraction == pytest.approx(
        fraction, abs=5 * np.sqrt(fraction * (1 - fraction) / links) + 0.01)
    # The mean of n exponential draws has relative standard error 1 / sqrt(n).
    assert estimate.nlos_gamma == pytest.approx(gamma, rel=5 / np.sqrt(blocked) + 0.05)


@pytest.mark.parametrize('outliers', [0.0, 0.05, 0.25])
def test_the_outliers_share_is_learned_and_leaves_sigma_alone(outliers):
    """
    Outliers of metres, of either sign, are a share of their own, not a larger sigma.

    A fifth of the ranges outliers made sigma a metre without their term. The share is
    never learned below the judge's prior (``OUTLIER_FRACTION``).
    """
    learner, links = learn(0.1, fraction=0.1, outliers=outliers)
    estimate = learner.estimate
    clear = (1.0 - outliers) * links
    assert estimate.sigma == pytest.approx(0.1, rel=10 / np.sqrt(2 * clear))
    # A binomial share, five standard errors; outliers within a few sigmas pass as clear.
    tolerance = 5 * np.sqrt(max(outliers, OUTLIER_FRACTION) / links) + 0.01
    assert estimate.outliers == pytest.approx(max(outliers, OUTLIER_FRACTION), abs=tolerance)
    assert estimate.outliers >= OUTLIER_FRACTION
    assert estimate.as_options()['outlier_fraction'] == estimate.outliers


def test_sigma_growing_with_distance_is_learned():
    learner, links = learn(0.03, eta=0.01)
    distances = np.array([5.0, 20.0, 35.0])
    truth = np.hypot(0.03, 0.01 * distances)
    np.testing.assert_allclose(learner.estimate.link_sigma(distances), truth, rtol=0.1)


def test_fit_residuals_are_corrected_for_the_parameters_fitted():
    """Residuals of a least-squares fit of d parameters to n ranges shrink by (n - d) / n."""
    rng = np.random.default_rng(3)
    n, dof, factors = 30, 6, []
    for _ in range(400):
        errors = 0.2 * rng.standard_normal(n)
        design = rng.standard_normal((n, dof))
        excess = errors - design @ np.linalg.lstsq(design, errors, rcond=None)[0]
        factors.append(frame_scale(excess, np.full(n, 0.2), dof))
    # Medians of ~n/2 residuals: each factor scatters ~0.2; 400 of them, 5 errors.
    assert np.mean(factors) == pytest.approx(1.0, abs=5 * 0.25 / np.sqrt(400) + 0.02)


def test_exact_ranges_never_make_the_learner_claim_millimetres():
    learner, _ = learn(1e-6)
    assert learner.estimate.sigma == pytest.approx(CONFIGURED.sigma / 20)
    exact, _ = learn(0.0)                   # no residual: nothing learned
    assert exact.estimate.sigma == CONFIGURED.sigma


def test_too_short_residuals_alone_set_the_scale():
    """Blocked links are too long: however many, they do not inflate sigma."""
    excess = np.r_[0.1 * np.linspace(-2, 2, 21), np.full(20, 5.0)]
    sigma = np.full(excess.size, 0.1)
    assert frame_scale(excess, sigma, 0) == pytest.approx(
        np.median(0.1 * np.linspace(0.2, 2, 10)) / 0.1 / 0.6745, rel=1e-3)


def run_cycle(model, true_sigma, frames=300, seed=0, **options):
    """Chain on a boom moving slowly, true range sigma given; (estimator, errors, bounds)."""
    rng = np.random.default_rng(seed)
    estimator = PostureEstimator(model, 'chain', **options)
    errors, bounds = [], []
    for k in range(frames):
        slew = 0.2 + 0.002 * k
        pitches = np.radians([45.0, 20.0, 0.0, -20.0, -40.0]) + 0.001 * k
        joints = model.forward_kinematics(slew, pitches)
        ranges = model.ranges(joints) + true_sigma * rng.standard_normal(
            (model.n_sections, model.n_anchors))
        estimator.update(ranges, stamp=0.1 * k)
        estimate = estimator.last_diagnostics['estimate']
        errors.append(np.sqrt(np.mean(np.sum((estimate - joints) ** 2, axis=1))))
        bounds.append(crlb(model, slew, pitches, true_sigma).rmse)
    return estimator, np.array(errors), np.array(bounds)


@pytest.mark.parametrize('told', [0.01, 1.0])
def test_a_sigma_told_ten_times_wrong_is_learned_without_gross_errors(told):
    model = truck_pump()
    estimator, errors, bounds = run_cycle(model, 0.1, sigma=told)
    assert np.all(errors < 5 * bounds)
    links = estimator.noise.links
    assert estimator.noise.sigma == pytest.approx(0.1, rel=10 / np.sqrt(2 * links))
    diagnostics = estimator.last_diagnostics
    # The noise the last frame was judged with: learned from the frames before it.
    assert diagnostics['noise'].sigma == pytest.approx(0.1, rel=10 / np.sqrt(2 * links))
    assert report(diagnostics, model.arm_lengths)['range sigma [m]'] == \
        f'{diagnostics["noise"].sigma:.4f}'
    # Once learned, the frames pass the checks the told value failed.
    assert diagnostics['valid']


def test_told_noise_stays_when_learning_is_off():
    estimator, _, _ = run_cycle(truck_pump(), 0.3, frames=50, learn_noise=False)
    assert estimator.noise == RangeNoiseEstimate(0.1, 0.0, 0.1, 1.0)


def test_cold_starts_on_the_authors_geometry_learn_sigma_from_the_frame():
    """Told 0.1 m when sigma is 1 m: every frame from scratch, and no gross error."""
    model, joints = xie3dim()
    rng = np.random.default_rng(5)
    for _ in range(20):
        estimator = PostureEstimator(model, 'chain')
        estimator.update(model.ranges(joints) + rng.standard_normal((5, 4)))
        error = np.sqrt(np.mean(np.sum((estimator.last_diagnostics['estimate'] - joints) ** 2,
                                       axis=1)))
        assert error < 3.0                  # the bound here is ~0.9 m
        assert estimator.noise.sigma > 0.3


def test_reconfiguring_the_noise_restarts_learning_and_learn_noise_is_checked():
    model = truck_pump()
    estimator, _, _ = run_cycle(model, 0.3, frames=30)
    assert estimator.noise.links > 0
    estimator.reconfigure(nlos_gamma=2.0)
    assert estimator.noise == RangeNoiseEstimate(0.1, 0.0, 0.1, 2.0)
    with pytest.raises(ValueError, match='learn_noise'):
        PostureEstimator(model, 'chain', learn_noise='yes')
