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

"""
What the estimator learns of its ranges' errors while running, in one object.

The range noise (``noise_learning.NoiseLearner``: sigma, eta and the NLOS mixture, from
the residuals' scale) and the bias common to every link (``bias_learning.BiasLearner``: an
offset, a growth with range and the moving anchors' shifts, from accepted frames) start
from what the estimator is told and are kept across a reconfiguration that tells the same.
``PostureEstimator`` owns one when ``learn_noise`` is on and gives what it learned to its
method and its integrity checks.
"""
from dataclasses import replace

from epp_ros.core.estimation.bias_learning import BiasLearner
from epp_ros.core.estimation.noise_learning import NoiseLearner, RangeNoiseEstimate

__all__ = ['LearnedErrors', 'told_noise']

#: The told values the common bias's learning starts from.
BIAS_SETTINGS = ('link_bias_std', 'common_bias_std', 'bias_slope_std', 'anchor_std')


def told_noise(told):
    """Return the range noise an estimator is told (:class:`RangeNoiseEstimate`)."""
    return RangeNoiseEstimate(told['sigma'], told['eta'], told['nlos_fraction'],
                              told['nlos_gamma'])


class LearnedErrors:
    """
    The range noise and the common range bias, learned from the told values on.

    Parameters
    ----------
    model : BoomModel
    told : dict
        The estimator's told options (its noise model's and the bias priors).
    moving : tuple of int
        The anchors that may stand elsewhere than configured.
    learn_anchors : bool
        Learn their shifts too; False: only count them (``anchor_std``, then what the
        frames show) in what is unknown of the bias.

    """

    def __init__(self, model, told, moving, learn_anchors=False):
        self.told = dict(told)
        self.learn_anchors = bool(learn_anchors)
        self.noise_learner = NoiseLearner(told_noise(told))
        self.bias_learner = BiasLearner(
            told['common_bias_std'], told['bias_slope_std'], told['link_bias_std'],
            model.n_sections * model.n_anchors, anchor_std=told['anchor_std'], moving=moving,
            n_anchors=model.n_anchors, learn_anchors=learn_anchors)

    def learned_from(self, told, learn_anchors=False):
        """Whether what was learned started from these settings (else it starts over)."""
        return (self.noise_learner.configured == told_noise(told)
                and all(told[name] == self.told[name] for name in BIAS_SETTINGS)
                and bool(learn_anchors) == self.learn_anchors)

    @property
    def noise(self):
        """Return the range noise learned so far (:class:`RangeNoiseEstimate`)."""
        return self.noise_learner.estimate

    @property
    def settled(self):
        """Whether the noise has been learned from enough links to trust its scale."""
        return self.noise_learner.settled

    def observe_noise(self, excess, fitted, dof):
        """Add a frame's range residuals; True when the noise learned changed."""
        return self.noise_learner.observe(excess, fitted, dof)

    def rescale(self, factor):
        """Scale the noise learned by ``factor`` (a frame far noisier than told)."""
        self.noise_learner.rescale(factor)

    @property
    def range_bias(self):
        """Return the common range bias taken off (offset m, slope m/m at 20 m), a copy."""
        return self.bias_learner.estimate[:2].copy()

    @property
    def anchor_shifts(self):
        """Return how far each moving anchor stands from where configured (n, 3), m."""
        return self.bias_learner.anchor_shifts.copy()

    @property
    def seen_shifts(self):
        """Return how far the frames show each moving anchor to stand (n, 3), m, a copy."""
        return self.bias_learner.seen_shifts.copy()

    def bias_covariance(self):
        """Return what is still unknown of the common bias (its covariance)."""
        return self.bias_learner.covariance()

    @property
    def biased(self):
        """Whether any common bias or anchor shift has been learned (else nothing to take off)."""
        return bool(self.bias_learner.estimate.any())

    def unbiased(self, measurements, directions):
        """
        Return ``measurements`` with the learned bias taken off the ranges.

        ``directions`` (p, m, 3): from each anchor to each tag, of the last posture that
        fitted its frame (None: an anchor's shift waits for one).
        """
        ranges = measurements.ranges
        return replace(measurements,
                       ranges=ranges - self.bias_learner.correction(ranges, directions))

    def observe_bias(self, jacobian, sigma, scaled, fitted, links, directions):
        """Add a frame's line-of-sight residuals (``BiasLearner.observe``); True if changed."""
        return self.bias_learner.observe(jacobian, sigma, scaled, fitted, links, directions)
