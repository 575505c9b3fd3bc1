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
The range noise of the field, learned from the estimator's own residuals while it runs.

Nobody knows the range noise of a pump on site: it changes with distance, weather, the
boom's own shadow and the firmware. :class:`NoiseLearner` fits the model the estimators use
(``core.nlos``: a range is ``d + s(d) N + X``, ``s(d) = sqrt(sigma^2 + (eta d)^2)``, ``X``
an exponential excess of mean ``nlos_gamma`` on a fraction ``nlos_fraction`` of the links,
and a share ``outliers`` no noise explains, of either sign: a broad Gaussian) to the
residuals of the last frames by expectation-maximisation:

- each estimate starts from a scale no blocked link can inflate: blocked ranges are too long,
  so the too-short residuals are line of sight, and their median is 0.674 s;
- E-step: each link's probability of being blocked, and of being an outlier, under the
  current mixture;
- M-step: ``sigma^2`` and ``eta^2`` by weighted least squares of the squared line-of-sight
  residuals on ``(1, d^2)``; the fraction and mean excess from the blocked weights, and the
  outliers' share from theirs, each pulled toward the configured value by a few
  pseudo-links so that a window without a blocked link does not drive them to zero.
  The outliers' share is never learned below the configured one (the judge's prior,
  ``NlosMixture.judged``): a site may have more than the recorded rate, never trust less.
  Without the outliers' term, a site where a fifth of the ranges are outliers of metres
  would have its sigma learned at a metre, and every frame refused as unobservable.

Residuals of a fit are smaller than the errors: the fit absorbs ``dof`` of them per frame,
which the variance is corrected for. The configured values are the start, and stay the
estimate until enough links have been seen.
"""
from collections import deque
from dataclasses import dataclass

from epp_ros.core.model.nlos import NlosMixture, OUTLIER_FRACTION
import numpy as np

__all__ = ['RangeNoiseEstimate', 'NoiseLearner', 'frame_scale']

#: Median of the absolute value of a standard normal draw.
_HALF_NORMAL_MEDIAN = 0.6744897501960817
#: Bounds of what is learned: sigma in metres, eta, fraction, gamma in metres.
SIGMA_RANGE = (1e-3, 20.0)
#: Sigma is not learned below the configured one over this: exact or quantised ranges must
#: not make the estimator claim millimetres.
SIGMA_FLOOR_FACTOR = 20.0
ETA_RANGE = (0.0, 0.2)
FRACTION_RANGE = (0.01, 0.5)
#: The largest share of the ranges learned to be outliers.
OUTLIERS_MAX = 0.3
#: Pseudo-links toward the configured NLOS fraction and mean excess, and outliers' share.
PRIOR_LINKS = 20.0


@dataclass(frozen=True)
class RangeNoiseEstimate:
    """What is known of the tag-anchor range noise, and from how many links."""

    sigma: float                #: m, additive standard deviation
    eta: float                  #: growth of the standard deviation with the range
    nlos_fraction: float        #: probability that a link is blocked
    nlos_gamma: float           #: m, mean excess of a blocked link
    links: int = 0              #: residuals it rests on (0: the configured values)
    outliers: float = OUTLIER_FRACTION     #: share of ranges no noise explains (the judge's)

    def link_sigma(self, distances):
        """Return the standard deviation (m) of ranges of the given lengths (m, any shape)."""
        return np.hypot(self.sigma, self.eta * np.asarray(distances, dtype=float))

    def ratio(self, other, distance=10.0):
        """Return the larger over the smaller sigma of the two estimates at ``distance`` m."""
        mine, theirs = self.link_sigma(distance), other.link_sigma(distance)
        return float(max(mine, theirs) / min(mine, theirs))

    def as_options(self):
        """Return the methods' noise (``sigma``, ``eta``, ``nlos_*``, ``outlier_fraction``)."""
        return {'sigma': self.sigma, 'eta': self.eta, 'nlos_fraction': self.nlos_fraction,
                'nlos_gamma': self.nlos_gamma, 'outlier_fraction': self.outliers}


def frame_scale(excess, link_sigma, dof, too_short_only=True):
    """
    Robust factor by which the given link sigmas are off, or NaN with too few residuals.

    The median size of residuals in units of ``link_sigma`` is 0.674 when the sigmas are
    right, corrected for the ``dof`` parameters the fit spent. By default only the too-short
    residuals count: no blocked link is among them. A fit made with a sigma far too small
    is not one to trust that way: it leaves most of the error in links it calls blocked,
    too long; then all residuals are counted (``too_short_only=False``).

    Parameters
    ----------
    excess : ndarray, shape (n,)
        Measured minus fitted ranges, metres.
    link_sigma : ndarray, shape (n,)
        Their standard deviations as currently believed, metres.
    dof : int
        Parameters the fit spent on them.
    too_short_only : bool
        Count only the residuals below zero.

    """
    excess, link_sigma = _finite(excess, link_sigma)
    counted = excess < 0 if too_short_only else np.ones(excess.size, bool)
    if counted.sum() < 3 or excess.size <= dof + 2:
        return float('nan')
    scale = np.median(np.abs(excess[counted]) / link_sigma[counted]) / _HALF_NORMAL_MEDIAN
    return float(scale * np.sqrt(excess.size / (excess.size - dof)))


def _finite(excess, distances):
    excess = np.asarray(excess, dtype=float).ravel()
    distances = np.asarray(distances, dtype=float).ravel()
    keep = np.isfinite(excess) & np.isfinite(distances)
    return excess[keep], distances[keep]


class NoiseLearner:
    """
    Sliding-window EM estimate of the range noise from fit residuals.

    Parameters
    ----------
    configured : RangeNoiseEstimate
        The configured noise: the start, and the prior of the NLOS terms.
    window : int
        Frames of residuals kept.
    every : int
        Frames between re-estimates once settled.
    settle_links : int
        Residuals needed before the estimate replaces the configured values.
    rounds : int
        EM rounds per re-estimate.

    """

    def __init__(self, configured, window=100, every=10, settle_links=150, rounds=4):
        self.configured = configured
        self.estimate = configured
        self.window = int(window)
        self.every = int(every)
        self.settle_links = int(settle_links)
        self.rounds = int(rounds)
        self._frames = deque(maxlen=self.window)
        self._since = 0

    @property
    def settled(self):
        """Return whether the estimate rests on the window's residuals."""
        return self.estimate.links >= self.settle_links

    def links(self):
        """Return the number of residuals in the window."""
        return sum(frame[0].size for frame in self._frames)

    def observe(self, excess, distances, dof):
        """
        Add one frame's tag-anchor residuals; return whether the estimate changed.

        Parameters
        ----------
        excess : ndarray, shape (n,)
            Measured minus fitted range of each link used, metres (NaN ignored).
        distances : ndarray, shape (n,)
            The fitted range of each link, metres.
        dof : int
            Parameters the fit spent on this frame.

        """
        excess, distances = _finite(excess, distances)
        if excess.size <= dof:
            return False
        self._frames.append((excess, distances, int(dof)))
        self._since += 1
        due = self._since >= self.every or not self.settled
        if not due or self.links() < self.settle_links:
            return False
        self._since = 0
        before = self.estimate
        self.estimate = self._fit()
        return self.estimate != before

    def rescale(self, factor):
        """Scale the current sigmas by ``factor`` (a frame's own scale, before settling)."""
        self.estimate = self._scaled(self.estimate, factor, self.estimate.links)

    def _fit(self):
        excess = np.concatenate([frame[0] for frame in self._frames])
        distances = np.concatenate([frame[1] for frame in self._frames])
        dof = sum(frame[2] for frame in self._frames)
        # Each round starts from a scale no blocked link inflates.
        factor = frame_scale(excess, self.estimate.link_sigma(distances), dof)
        if not np.isfinite(factor):
            return self.estimate
        current = self._scaled(self.estimate, factor, excess.size)
        for _ in range(self.rounds):
            current = self._em_round(current, excess, distances, dof)
        return current

    def _sigma(self, sigma):
        """Return ``sigma`` within the bounds of what is learned."""
        low = max(SIGMA_RANGE[0], self.configured.sigma / SIGMA_FLOOR_FACTOR)
        return float(np.clip(sigma, low, SIGMA_RANGE[1]))

    def _scaled(self, estimate, factor, links):
        """Return ``estimate`` with its sigmas times ``factor`` (and gamma kept above 2 sigma)."""
        sigma = self._sigma(estimate.sigma * factor)
        return RangeNoiseEstimate(sigma, float(np.clip(estimate.eta * factor, *ETA_RANGE)),
                                  estimate.nlos_fraction, max(estimate.nlos_gamma, 2.0 * sigma),
                                  links, estimate.outliers)

    def _em_round(self, current, excess, distances, dof):
        """One E and M step from ``current``."""
        sigma_links = current.link_sigma(distances)
        scaled = excess / sigma_links
        mixture = NlosMixture(*_clip_nlos(current.nlos_fraction, current.nlos_gamma),
                              outliers=current.outliers)
        blocked, outlying = mixture.bind(sigma_links).posteriors(scaled)
        # A residual far too short is no range the model explains: not evidence of sigma.
        line_of_sight = np.maximum(1.0 - blocked - outlying, 0.0) * (scaled > -8.0)
        used = line_of_sight.sum()
        correction = used / max(used - dof, 1.0)
        sigma_sq, eta_sq = _variance_fit(correction * excess ** 2, distances ** 2,
                                         line_of_sight / sigma_links ** 4)
        blocked_total = blocked.sum()
        fraction = ((blocked_total + PRIOR_LINKS * self.configured.nlos_fraction)
                    / (excess.size + PRIOR_LINKS))
        gamma = ((np.sum(blocked * np.maximum(excess, 0.0))
                  + PRIOR_LINKS * self.configured.nlos_gamma) / (blocked_total + PRIOR_LINKS))
        prior = min(self.configured.outliers, OUTLIERS_MAX)
        outliers = float(np.clip((outlying.sum() + PRIOR_LINKS * prior)
                                 / (excess.size + PRIOR_LINKS), prior, OUTLIERS_MAX))
        sigma = self._sigma(np.sqrt(sigma_sq))
        eta = float(np.clip(np.sqrt(eta_sq), *ETA_RANGE))
        fraction, gamma = _clip_nlos(fraction, max(gamma, 2.0 * sigma))
        return RangeNoiseEstimate(sigma, eta, fraction, gamma, excess.size, outliers)


def _clip_nlos(fraction, gamma):
    return float(np.clip(fraction, *FRACTION_RANGE)), float(max(gamma, 1e-3))


def _variance_fit(squares, distances_sq, weights):
    """
    Non-negative weighted least squares of ``squares ~ a + b distances_sq``; (a, b).

    The squares of Gaussian residuals have variance ``2 s^4``, hence weights ``1 / s^4``.
    """
    design = np.column_stack([np.ones_like(distances_sq), distances_sq])
    root = np.sqrt(weights)
    spread = np.ptp(distances_sq) if distances_sq.size else 0.0
    if spread > 1.0:
        solution, *_ = np.linalg.lstsq(design * root[:, None], squares * root, rcond=None)
        if solution[0] > 0 and solution[1] >= 0:
            return float(solution[0]), float(solution[1])
    # One term alone: all additive (or, with a negative constant, all range-dependent).
    additive = float(np.sum(weights * squares) / max(np.sum(weights), 1e-300))
    return additive, 0.0
