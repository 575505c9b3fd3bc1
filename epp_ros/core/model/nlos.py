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
Range errors: a Gaussian, sometimes an exponential excess (NLOS), rarely an outlier.

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

Real links also have outliers of either sign (a few frames per link-hour, up to +-3.3 m
in a public DW1000 recording; ``FieldEffects.outlier_rate``): a third, broad Gaussian of
``outlier_sigma`` on a share ``outliers`` of the ranges (:meth:`NlosMixture.judged`),
without which one short range is a Gaussian impossibility that moves every joint to
explain it.
"""
from copy import copy
from dataclasses import dataclass, replace
from functools import cached_property, lru_cache

from epp_ros.core.model.vectors import norms
from epp_ros.core.solvers.compiled import kernel, plain
import numpy as np
from scipy.special import log_ndtr

__all__ = ['NlosMixture', 'LinkLoss', 'range_excess']

_HALF_LOG_2PI = 0.5 * np.log(2.0 * np.pi)

#: Closest a link's own prior NLOS probability comes to 0 or 1.
PRIOR_LIMIT = 1e-6

#: Prior share of ranges that are outliers: twice the recorded rate (33 per link-hour of
#: 1-4 frames at 10 Hz is 0.2 %), as sites differ.
OUTLIER_FRACTION = 0.005

#: m, spread of an outlier's error: the recorded ones reach +-3.3 m.
OUTLIER_SIGMA = 2.0

#: An outlier's spread in the range's own sigmas, at least.
OUTLIER_SPREAD = 10.0
#: Links of at most this many ranges have their bound losses kept (:meth:`NlosMixture.bind`).
BOUND_SIZE = 256
#: The compiled twin of :meth:`LinkLoss.at_points` (``solvers.compiled``).
KERNEL = 'epp_ros.core.model.compiled_nlos'


def _outlier_ratio(sigma, outlier_sigma):
    """Return a range's sigma over an outlier's spread (<= 1 / OUTLIER_SPREAD)."""
    return sigma / np.hypot(outlier_sigma, OUTLIER_SPREAD * sigma)


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
    distance = norms(np.asarray(points)[..., None, :] - anchors)
    return np.where(np.isfinite(ranges), ranges - distance, 0.0) / sigma


@dataclass(frozen=True)
class NlosMixture:
    """
    Prior NLOS probability of a link, mean NLOS excess (metres), and prior outlier share.

    ``fraction=0`` and ``outliers=0`` is plain Gaussian least squares. An outlier's spread
    is ``outlier_sigma`` or ten of the range's sigmas, whichever is more: a range no noise
    explains.

    The estimator's mixture leaves ``outliers`` at 0, and its judge adds them
    (:meth:`judged`): that loss is flat far out, and a fit under it alone, from a start a
    few sigmas off, would stop where the ranges it has not reached yet look like
    outliers. So fits descend the mixture without outliers first and the judge's after
    (``chain.judged_minimum``), and every fit, rival and check is weighed with the
    judge's: one short range neither pulls a posture to a fold that explains it nor
    refuses one that fits every other range.
    """

    fraction: float = 0.1
    gamma: float = 1.0
    outliers: float = 0.0
    outlier_sigma: float = OUTLIER_SIGMA

    def __post_init__(self):
        if not 0.0 <= self.fraction < 1.0:
            raise ValueError(f'nlos_fraction must be in [0, 1), got {self.fraction}')
        if not self.gamma > 0.0:
            raise ValueError(f'nlos_gamma must be > 0 m, got {self.gamma}')
        if not 0.0 <= self.outliers < 1.0 - self.fraction:
            raise ValueError(f'outliers must be in [0, 1 - nlos_fraction), got {self.outliers}')
        if not self.outlier_sigma > 0.0:
            raise ValueError(f'outlier_sigma must be > 0 m, got {self.outlier_sigma}')

    def judged(self, share=OUTLIER_FRACTION):
        """
        Return the judge's mixture: this one with a share of the ranges outliers.

        Parameters
        ----------
        share : float
            The outliers' share, in [0, 1 - fraction): :data:`OUTLIER_FRACTION` by default,
            the share learned on site (``NoiseLearner``) where there are more.

        Returns
        -------
        NlosMixture
            This mixture itself when Gaussian (plain least squares stays so) or when it has
            outliers of its own.

        Raises
        ------
        ValueError
            Naming ``outlier_fraction``, when ``share`` is outside its range.

        """
        if not 0.0 <= share < 1.0 - self.fraction:
            raise ValueError(f'outlier_fraction: must be in [0, 1 - nlos_fraction), got '
                             f'{share!r}')
        if self.gaussian or self.outliers:
            return self
        return replace(self, outliers=float(share))

    @property
    def gaussian(self):
        """Whether this is plain least squares (no NLOS, no outliers)."""
        return self.fraction == 0.0 and self.outliers == 0.0

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
        ``fraction`` is 0. Without a prior, a frame's few dozen sigmas are bound once and
        the loss is shared (its arrays read-only): fits and checks bind the same ones many
        times.
        """
        sigma = np.asarray(sigma, dtype=float)
        if prior is None and sigma.size <= BOUND_SIZE:
            return _bound(self, sigma.shape, sigma.tobytes())
        return LinkLoss(self, sigma, prior)

    def approximate_loss(self, excess, sigma):
        """
        Return a cheap stand-in for :meth:`loss` (cost only), for scoring many candidates.

        The largest of the mixture terms instead of their sum, and the blocked one only
        for too-long ranges and without its Gaussian tail: the loss less
        ``-log(1 - fraction - outliers)`` to within ``log 3``.
        """
        s = np.asarray(excess, dtype=float)
        sigma = np.asarray(sigma, dtype=float)
        cost = 0.5 * s ** 2
        clear = 1.0 - self.fraction - self.outliers      # each prior relative to this one
        if self.outliers:
            ratio = _outlier_ratio(sigma, self.outlier_sigma)
            cost = np.minimum(cost, 0.5 * (ratio * s) ** 2
                              - np.log(self.outliers / clear * ratio))
        if self.fraction == 0.0:
            return cost
        inverse_g = sigma / self.gamma
        offset = (np.log(self.fraction / clear) + _HALF_LOG_2PI + np.log(inverse_g)
                  + 0.5 * inverse_g ** 2)
        return np.where(s > 0.0, np.minimum(cost, inverse_g * s - offset), cost)


def _blocked_peak(a, iterations=60):
    """
    Return the most ``log Phi(t) - a t`` reaches over t, for each ``a`` > 0.

    Where ``pdf(t) / cdf(t) = a``: Newton's method on the log of that ratio, concave and
    falling, lands right of the root from ``-a`` and then falls to it.
    """
    t = -np.asarray(a, dtype=float)
    for _ in range(iterations):
        mills = np.exp(-0.5 * t ** 2 - _HALF_LOG_2PI - log_ndtr(t))
        step = (np.log(mills) - np.log(a)) / (-t - mills)
        t = t - step
        if np.all(np.abs(step) <= 1e-12 * (1.0 + np.abs(t))):
            break
    return log_ndtr(t) - a * t


def _candidates(points, ranges, anchors, tags):
    """
    Return :meth:`LinkLoss.at_points`' arguments as arrays, their shapes checked.

    The compiled kernel reads them unchecked: a tag or anchor out of range would read
    other memory, not fail.
    """
    points, ranges, anchors = (np.asarray(a, dtype=float) for a in (points, ranges, anchors))
    if ranges.ndim != 2 or anchors.shape != (ranges.shape[1], 3) or points.shape[-1:] != (3,):
        raise ValueError(f'candidates: points (..., 3), ranges (q, m) and anchors (m, 3), '
                         f'got {points.shape}, {ranges.shape} and {anchors.shape}')
    if tags is None:
        if points.shape[-2:-1] != ranges.shape[:1]:
            raise ValueError(f'candidates: points (..., q, 3) for ranges (q, m), got '
                             f'{points.shape} and {ranges.shape}')
        return points, ranges, anchors, None
    tags = np.asarray(tags)
    if (tags.ndim != 1 or points.shape != tags.shape + (3,)
            or not (tags.size == 0 or np.issubdtype(tags.dtype, np.integer))
            or np.any((tags < 0) | (tags >= len(ranges)))):
        raise ValueError(f'candidates: points (n, 3) and tags (n,) each a row of ranges '
                         f'(q = {len(ranges)}), got {points.shape} and {tags.tolist()}')
    return points, ranges, anchors, tags.astype(np.int64)


@lru_cache(maxsize=64)
def _bound(mixture, shape, sigma_bytes):
    """Return ``LinkLoss(mixture, sigma)`` of the sigmas ``sigma_bytes`` of ``shape``, kept."""
    loss = LinkLoss(mixture, np.frombuffer(sigma_bytes).reshape(shape))
    for value in vars(loss).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return loss


class LinkLoss:
    """
    :meth:`NlosMixture.loss` for links of given sigmas, called on their excesses.

    Per-link constants (and the loss's value and slope at zero, when first called) are
    computed once, which matters inside an iterative fit where the same links are
    evaluated many times.
    ``off_line`` is the mean prior share of the links blocked or outliers (0 for a
    Gaussian loss): how many a fit may set aside by chance.
    """

    def __init__(self, mixture, sigma, prior=None):
        self.sigma = np.asarray(sigma, dtype=float)
        self._kernel_sigmas = None
        self.gaussian = mixture.gaussian
        self.off_line = 0.0
        if self.gaussian:
            return
        sigma = self.sigma
        self.inverse_g = sigma / mixture.gamma
        if prior is None or mixture.fraction == 0.0:
            prior = np.full(sigma.shape, mixture.fraction)
        else:   # certainty either way would make the loss flat or the fit blind
            prior = np.clip(np.asarray(prior, dtype=float), PRIOR_LIMIT,
                            1.0 - mixture.outliers - PRIOR_LIMIT)
        self.los_offset = np.log1p(-prior - mixture.outliers)
        self.off_line = float(np.mean(prior)) + mixture.outliers
        self.evidence_offset = (_HALF_LOG_2PI + np.log(self.inverse_g)
                                + 0.5 * self.inverse_g ** 2)
        with np.errstate(divide='ignore'):      # no NLOS: its term is -inf
            self.blocked_offset = np.log(prior) + self.evidence_offset
            # A broad Gaussian, in units of sigma and scaled like the others.
            self.outlier_ratio = _outlier_ratio(sigma, mixture.outlier_sigma)
            self.outlier_offset = np.log(mixture.outliers * self.outlier_ratio)

    def at_points(self, points, ranges, anchors, tags=None):
        """
        Return the cost of tags' ranges, summed over the anchors, at candidate positions.

        The ranges' sigmas are this loss's (one, or one per range). Compiled where the
        kernels are (``solvers.compiled``): the fold searches and the integrity checks score
        many candidates at once (a joint's other folds, the tip all round its hinge, whole
        postures).

        Parameters
        ----------
        points : ndarray, shape (..., q, 3), or (n, 3) with ``tags``
            Candidate positions of the q tags (or of tag ``tags[i]``), metres.
        ranges : ndarray, shape (q, m)
            The tags' measured ranges, metres; NaN where none (it scores 0).
        anchors : ndarray, shape (m, 3)
            The anchors, metres.
        tags : ndarray of int, shape (n,), optional
            Each point's row of ``ranges``.

        Returns
        -------
        ndarray, shape (..., q) or (n,)

        """
        points, ranges, anchors, rows = _candidates(points, ranges, anchors, tags)
        if self.sigma.size != 1 and self.sigma.shape != ranges.shape:
            raise ValueError(f'a loss bound to sigmas of shape {self.sigma.shape} scores '
                             f'ranges of shape {ranges.shape}: one sigma, or one per range')
        compiled = kernel(KERNEL)
        if compiled is None:
            sigma = np.broadcast_to(self.sigma, ranges.shape)
            if rows is None:
                return np.sum(self(range_excess(points, anchors, ranges, sigma))[0], axis=-1)
            excess = range_excess(points, anchors, ranges[rows], sigma[rows])   # (n, m)
            return np.sum(self._rows(rows)(excess)[0], axis=-1)
        if rows is None:
            shape = points.shape[:-1]
            rows = np.arange(points.size // 3) % ranges.shape[0]
            points = points.reshape(-1, 3)
        else:
            shape = rows.shape
        return compiled.tag_losses(plain(points), plain(rows, np.int64), plain(ranges),
                                   self._kernel_sigma(ranges.shape), plain(anchors),
                                   compiled.loss_terms(self)).reshape(shape)

    def _kernel_sigma(self, shape):
        """Return the sigmas broadcast to ``shape`` (q, m) as the kernel reads them; kept."""
        kept = self._kernel_sigmas
        if kept is None or kept.shape != shape:
            kept = self._kernel_sigmas = plain(np.broadcast_to(self.sigma, shape))
        return kept

    @cached_property
    def floor(self):
        """
        No excess costs a link less than this, nats (shaped like the sigmas; 0: Gaussian).

        The tilted loss (:meth:`__call__`) falls below zero where a link's learned shares
        are large: its tilt, the slope at zero, grows with them. Its mixture's density is
        at most the sum of each term's own peak, the tilt added: the line of sight's at
        the slope at zero, the outlier's likewise in its own sigmas, the blocked one where
        the normal's pdf / cdf at ``s - inverse_g`` equals ``inverse_g`` less the slope.
        A bound from below, close where one term outweighs the others.
        """
        if self.gaussian:
            return np.zeros(self.sigma.shape)
        zero_cost, zero_slope = self.at_zero
        compiled = kernel(KERNEL)
        if compiled is not None:
            return compiled.link_floors(compiled.loss_terms(self)).reshape(zero_cost.shape)
        a = self.inverse_g - zero_slope         # > 0: the slope at zero is never positive
        peak = _blocked_peak(np.where(a > 0.0, a, 1.0))
        los = self.los_offset + 0.5 * zero_slope ** 2
        blocked = self.blocked_offset - a * self.inverse_g + peak
        outlier = self.outlier_offset + 0.5 * (zero_slope / self.outlier_ratio) ** 2
        floor = -np.logaddexp(np.logaddexp(los, blocked), outlier) - zero_cost
        return np.where(a > 0.0, floor, -np.inf)

    def _rows(self, rows):
        """Return this loss for the links of ``rows`` of its (q, m) sigmas: (n, m) each."""
        if self.sigma.ndim == 0:
            return self
        taken = copy(self)
        for name, value in vars(self).items():
            if isinstance(value, np.ndarray) and value.shape == self.sigma.shape:
                setattr(taken, name, value[rows])
            elif name == 'at_zero':
                setattr(taken, name, tuple(np.broadcast_to(v, self.sigma.shape)[rows]
                                           for v in value))
        taken._kernel_sigmas = None         # its own sigmas' shape, were it scored compiled
        return taken

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

    def _terms(self, s):
        """Log-weights (line of sight, blocked, outlier) of excesses ``s``, and z, log cdf(z)."""
        z = s - self.inverse_g
        log_cdf = log_ndtr(z)
        los = self.los_offset - 0.5 * s ** 2
        # Exponentially modified Gaussian, scaled by sqrt(2 pi) like the Gaussian term.
        blocked = self.blocked_offset - self.inverse_g * s + log_cdf
        outlier = self.outlier_offset - 0.5 * (self.outlier_ratio * s) ** 2
        return los, blocked, outlier, z, log_cdf

    def posteriors(self, excess):
        """
        Return the posterior probabilities that each link is NLOS, and that it is an outlier.

        ``excess`` in units of the links' sigmas, shaped like them; zeros for a Gaussian loss.
        """
        s = np.asarray(excess, dtype=float)
        if self.gaussian:
            return np.zeros_like(s), np.zeros_like(s)
        los, blocked, outlier, _, _ = self._terms(s)
        total = np.logaddexp(np.logaddexp(los, blocked), outlier)
        return np.exp(blocked - total), np.exp(outlier - total)

    def __call__(self, excess):
        """(cost, slope, nlos) of excesses shaped like the sigmas; see :meth:`NlosMixture.loss`."""
        s = np.asarray(excess, dtype=float)
        if self.gaussian:
            return 0.5 * s ** 2, s, np.zeros_like(s)
        return self._relative(s, *self.at_zero)

    @cached_property
    def at_zero(self):
        """Value and slope at zero excess (shaped like the sigmas), which the loss takes off."""
        cost, slope, _ = self._relative(np.zeros_like(self.inverse_g), 0.0, 0.0)
        return cost, slope

    def _relative(self, s, zero_cost, zero_slope):
        """Return :meth:`__call__` less ``zero_cost`` and ``zero_slope`` times the excess."""
        los, blocked, outlier, z, log_cdf = self._terms(s)
        total = np.logaddexp(np.logaddexp(los, blocked), outlier)
        nlos, outlying = np.exp(blocked - total), np.exp(outlier - total)
        mills = np.exp(-0.5 * z ** 2 - _HALF_LOG_2PI - log_cdf)         # pdf(z) / cdf(z)
        slope = ((1.0 - nlos - outlying) * s + nlos * (self.inverse_g - mills)
                 + outlying * self.outlier_ratio ** 2 * s - zero_slope)
        cost = -total - zero_cost - zero_slope * s
        return cost, slope, nlos
