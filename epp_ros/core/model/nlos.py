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
Range errors with non-line-of-sight links: a Gaussian, and sometimes an exponential excess.

A blocked UWB path is always longer than the straight one. The model of the paper's NLOS
experiment, and of ``simulate.RangeNoise``: a measured range is ``d + sigma N + X`` where
``X = 0`` on a line-of-sight link and ``X ~ Exponential(mean gamma)`` on a fraction of the
links. Its negative log-likelihood, as a loss on the excess ``e = measured - d``:

- is ``e^2 / (2 sigma^2)`` for short and slightly long ranges, as plain least squares;
- grows only like ``e / gamma`` for long ones, so a blocked link barely pulls the fit;
- gives each link's posterior probability of being NLOS, which is how links are flagged.

Minimising it is the maximum-likelihood estimate under that model (an exponentially
modified Gaussian mixture), rather than a threshold tuned by hand, with one change: the
likelihood peaks slightly past zero excess, so the loss is tilted by its slope at zero
(it moves a fit by about 1 % of sigma) for exact ranges to be fitted exactly.
"""
from dataclasses import dataclass

import numpy as np
from scipy.special import expit, log_ndtr

__all__ = ['NlosMixture', 'LinkLoss', 'range_excess']

_HALF_LOG_2PI = 0.5 * np.log(2.0 * np.pi)

#: Closest a link's own prior NLOS probability comes to 0 or 1.
PRIOR_LIMIT = 1e-6


def range_excess(points, anchors, ranges, sigma):
    """
    Return measured ranges less the distances from candidate points, in units of sigma.

    What the losses here take, for scoring where tags could be.

    Parameters
    ----------
    points : ndarray, shape (..., 3) or (..., q, 3)
        Candidate positions of one tag, or of q tags (one row each), metres.
    anchors : ndarray, shape (m, 3)
        The anchors, metres.
    ranges : ndarray, shape (m,) or (q, m)
        That tag's (those tags') measured ranges, metres, NaN where none.
    sigma : ndarray, shape like ``ranges``
        Their standard deviations, metres, finite.

    Returns
    -------
    ndarray, shape (..., m) or (..., q, m)
        ``(measured - distance) / sigma``; 0 where a range is missing, which every loss
        here scores 0.

    """
    distance = np.linalg.norm(np.asarray(points)[..., None, :] - anchors, axis=-1)
    return np.where(np.isfinite(ranges), ranges - distance, 0.0) / sigma


@dataclass(frozen=True)
class NlosMixture:
    """
    Prior NLOS probability of a link and mean NLOS excess (metres).

    ``fraction=0`` is plain Gaussian least squares.
    """

    fraction: float = 0.1
    gamma: float = 1.0

    def __post_init__(self):
        if not 0.0 <= self.fraction < 1.0:
            raise ValueError(f'nlos_fraction must be in [0, 1), got {self.fraction}')
        if not self.gamma > 0.0:
            raise ValueError(f'nlos_gamma must be > 0 m, got {self.gamma}')

    def loss(self, excess, sigma):
        """
        Loss, slope and NLOS probability of range excesses in units of their sigma.

        Parameters
        ----------
        excess : ndarray, shape (...)
            ``(measured - predicted) / sigma`` of each range.
        sigma : ndarray, shape (...) or float
            Each range's Gaussian standard deviation, metres.

        Returns
        -------
        cost : ndarray, shape (...)
            Negative log-likelihood less its value and slope at zero times the excess,
            so zero at zero; ``excess**2 / 2`` when ``fraction`` is 0.
        slope : ndarray, shape (...)
            Its derivative with respect to ``excess``, zero at zero.
        nlos : ndarray, shape (...)
            Posterior probability that each link is NLOS.

        """
        s = np.asarray(excess, dtype=float)
        return self.bind(np.broadcast_to(np.asarray(sigma, dtype=float), s.shape))(s)

    def bind(self, sigma, prior=None):
        """
        Return :meth:`loss` for ranges of fixed sigmas (any shape), its constants computed once.

        ``prior``: each range's own prior NLOS probability, shaped like ``sigma``, instead of
        ``fraction`` (a link's neighbours in time, ``core.blockage``); ignored when
        ``fraction`` is 0.
        """
        return LinkLoss(self, sigma, prior)

    def approximate_loss(self, excess, sigma):
        """
        Return a cheap stand-in for :meth:`loss` (cost only), for scoring many candidates.

        The larger of the two mixture terms instead of their sum, and the blocked one only
        for too-long ranges and without its Gaussian tail: the loss less ``-log(1 - fraction)``
        to within ``log 2``.
        """
        s = np.asarray(excess, dtype=float)
        if self.fraction == 0.0:
            return 0.5 * s ** 2
        inverse_g = np.asarray(sigma, dtype=float) / self.gamma
        offset = (np.log(self.fraction / (1.0 - self.fraction)) + _HALF_LOG_2PI
                  + np.log(inverse_g) + 0.5 * inverse_g ** 2)
        return np.where(s > 0.0, np.minimum(0.5 * s ** 2, inverse_g * s - offset), 0.5 * s ** 2)


class LinkLoss:
    """
    :meth:`NlosMixture.loss` for links of given sigmas, called on their excesses.

    Per-link constants (and the loss's value and slope at zero) are computed once, which
    matters inside an iterative fit where the same links are evaluated many times.
    """

    def __init__(self, mixture, sigma, prior=None):
        self.gaussian = mixture.fraction == 0.0
        if self.gaussian:
            return
        self.inverse_g = np.asarray(sigma, dtype=float) / mixture.gamma
        if prior is None:
            prior = mixture.fraction
        else:   # certainty either way would make the loss flat or the fit blind
            prior = np.clip(np.asarray(prior, dtype=float), PRIOR_LIMIT, 1.0 - PRIOR_LIMIT)
        self.los_offset = np.log1p(-prior)
        self.evidence_offset = (_HALF_LOG_2PI + np.log(self.inverse_g)
                                + 0.5 * self.inverse_g ** 2)
        self.blocked_offset = np.log(prior) + self.evidence_offset
        self.zero_cost, self.zero_slope = 0.0, 0.0
        self.zero_cost, self.zero_slope, _ = self(np.zeros_like(self.inverse_g))

    def log_likelihood_ratio(self, excess):
        """
        Return log p(excess | NLOS) / p(excess | line of sight), whatever the prior.

        ``excess`` in units of the links' sigmas, shaped like them; 0 for a Gaussian loss.
        """
        s = np.asarray(excess, dtype=float)
        if self.gaussian:
            return np.zeros_like(s)
        return (self.evidence_offset - self.inverse_g * s + log_ndtr(s - self.inverse_g)
                + 0.5 * s ** 2)

    def __call__(self, excess):
        """(cost, slope, nlos) of excesses shaped like the sigmas; see :meth:`NlosMixture.loss`."""
        s = np.asarray(excess, dtype=float)
        if self.gaussian:
            return 0.5 * s ** 2, s, np.zeros_like(s)
        z = s - self.inverse_g
        log_cdf = log_ndtr(z)
        los = self.los_offset - 0.5 * s ** 2
        # Exponentially modified Gaussian, scaled by sqrt(2 pi) like the Gaussian term.
        blocked = self.blocked_offset - self.inverse_g * s + log_cdf
        nlos = expit(blocked - los)
        mills = np.exp(-0.5 * z ** 2 - _HALF_LOG_2PI - log_cdf)         # pdf(z) / cdf(z)
        slope = (1.0 - nlos) * s + nlos * (self.inverse_g - mills) - self.zero_slope
        cost = -np.logaddexp(los, blocked) - self.zero_cost - self.zero_slope * s
        return cost, slope, nlos
