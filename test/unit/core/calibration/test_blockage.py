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

"""Blocked links persist: the links' NLOS states as a Markov chain, and the mixture's priors."""
from epp_ros.core.calibration.blockage import BlockageChain
from epp_ros.core.model.nlos import NlosMixture
import numpy as np
import pytest
from scipy.special import expit, logit

SIGMA, GAMMA, PERIOD = 0.1, 1.0, 0.1


def blocked_links(rng, frames, links, fraction, duration):
    """Return (frames, links) bool: two-state chains as ``simulate.FieldEffects``'s."""
    state = rng.random(links) < fraction
    states = []
    memory = np.exp(-PERIOD / (duration * (1.0 - fraction))) if duration else 0.0
    for _ in range(frames):
        state = rng.random(links) < fraction + (state - fraction) * memory
        states.append(state)
    return np.array(states)


def excesses(rng, blocked):
    """Return range excesses in metres: Gaussian, and an exponential excess when blocked."""
    return (rng.normal(0.0, SIGMA, blocked.shape)
            + blocked * rng.exponential(GAMMA, blocked.shape))


def log_ratios(excess, fraction):
    loss = NlosMixture(fraction, GAMMA).bind(np.full(excess.shape, SIGMA))
    return loss.log_likelihood_ratio(excess / SIGMA)


def test_the_likelihood_ratio_and_a_ranges_own_prior_are_bayes_rule():
    mixture = NlosMixture(0.2, GAMMA)
    excess = np.linspace(-3.0, 20.0, 50)
    sigma = np.full(excess.shape, SIGMA)
    _, _, nlos = mixture.loss(excess, sigma)
    ratio = mixture.bind(sigma).log_likelihood_ratio(excess)
    np.testing.assert_allclose(nlos, expit(logit(0.2) + ratio), rtol=1e-9, atol=1e-12)
    # A prior of its own per range: the fraction everywhere changes nothing.
    same = mixture.bind(sigma, np.full(excess.shape, 0.2))(excess)
    for got, want in zip(same, mixture.bind(sigma)(excess)):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    prior = np.linspace(0.01, 0.99, excess.size)
    _, _, own = mixture.bind(sigma, prior)(excess)
    np.testing.assert_allclose(own, expit(logit(prior) + ratio), rtol=1e-9, atol=1e-12)


def test_frames_on_their_own_keep_the_fraction_as_every_prior():
    rng = np.random.default_rng(0)
    blocked = blocked_links(rng, 200, 6, 0.2, 0.0)
    ratio = log_ratios(excesses(rng, blocked), 0.2)
    priors = BlockageChain(0.2, 0.0).priors(ratio, np.full(199, PERIOD))
    np.testing.assert_allclose(priors, 0.2, rtol=1e-12)


def test_the_duration_is_learned_and_the_priors_find_the_small_excesses_of_a_blocked_stretch():
    rng = np.random.default_rng(1)
    fraction, duration = 0.2, 3.0
    blocked = blocked_links(rng, 3000, 20, fraction, duration)
    excess = excesses(rng, blocked)
    ratio = log_ratios(excess, fraction)
    elapsed = np.full(blocked.shape[0] - 1, PERIOD)
    chain = BlockageChain.learn(fraction, ratio, elapsed)
    # The grid's nearest (10 frame periods is 1 s, 30 are 3 s): within its step of 3.
    assert 1.0 <= chain.duration <= 10.0
    prior = chain.priors(ratio, elapsed)
    alone = expit(logit(fraction) + ratio)
    together = expit(logit(prior) + ratio)
    small = blocked & (excess < 3 * SIGMA)      # a blocked range hard to tell by itself
    assert small.sum() > 500
    assert alone[small].mean() < 0.4 < 0.8 < together[small].mean()
    assert together[~blocked].mean() < 0.5 * alone[~blocked].mean()


def test_independent_blockages_are_learned_as_such():
    rng = np.random.default_rng(2)
    blocked = blocked_links(rng, 3000, 20, 0.2, 0.0)
    ratio = log_ratios(excesses(rng, blocked), 0.2)
    assert BlockageChain.learn(0.2, ratio, np.full(2999, PERIOD)).duration == 0.0


def test_a_gap_in_time_makes_the_states_on_either_side_independent():
    ratio = np.zeros((4, 1))
    ratio[:2] = 20.0            # two frames clearly blocked, then two unmeasured
    chain = BlockageChain(0.2, 3.0)
    near = chain.priors(ratio, np.array([0.1, 0.1, 0.1]))
    far = chain.priors(ratio, np.array([0.1, 1e4, 0.1]))
    assert near[2, 0] > 0.9 and abs(far[2, 0] - 0.2) < 1e-6
    # Frames at one instant: finite, and as sure as the chain allows.
    same = chain.priors(np.full((50, 1), 20.0), np.zeros(49))
    assert np.all(np.isfinite(same)) and same.min() > 0.9


@pytest.mark.parametrize('fraction, duration', [(0.0, 1.0), (1.0, 1.0), (0.2, -1.0),
                                                (float('nan'), 1.0), (0.2, float('nan'))])
def test_bad_chains_are_refused(fraction, duration):
    with pytest.raises(ValueError):
        BlockageChain(fraction, duration)
