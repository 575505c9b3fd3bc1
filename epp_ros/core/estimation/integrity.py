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
Integrity: whether an estimated posture may be published, and if not, why.

The posture feeds collision avoidance. A wrong posture flagged as wrong is safe; a wrong
posture reported as good is the worst outcome. Every estimate, whatever method made it, is
judged here on what its frame can show, so that the node and ``epp_bag eval`` agree:

- consistency: the range residuals must be explained by the noise the estimator was told
  (Gaussian errors, and an always-positive excess on a fraction of blocked links). Links
  more likely blocked than not are set aside; the rest must pass a chi-square test, overall
  and tag by tag (and their RMS the ``residual_*`` thresholds); how many were set aside a
  binomial test, and how long they are a gamma test;
- observability: the Cramér–Rao bound at the estimate, from the links kept and widened
  by the residuals' variance factor where they exceed their noise, must be finite
  and small, and no joint may have another position that fits about as well (a fold, the
  tip at another pitch, the whole boom mirrored, another fit the method's search found,
  the frame fitted without one tag's ranges), unless the boom could not have got there
  since the last accepted posture;
- plausibility: no joint below ``lowest_joint``, section lengths and the boom's vertical
  plane as configured, no jump faster than the boom moves.

Levels follow ``diagnostic_msgs``: a frame at ERROR is never published.
"""
from dataclasses import dataclass, field, fields, replace
import math
from typing import NamedTuple, Optional

from epp_ros.core.estimation.bias_learning import bias_design
from epp_ros.core.estimation.methods.chain import angles_from_joints, ChainMethod
from epp_ros.core.model.bounds import frame_bounds, RangeBiasPrior
from epp_ros.core.model.folds import fold_alternatives, tip_circle, tip_minima
from epp_ros.core.model.measurements import Measurements, Residuals, wrap_angle
from epp_ros.core.model.vectors import norms
import numpy as np
from scipy.special import betainc, gammaincc, gammainccinv

__all__ = ['OK', 'WARN', 'ERROR', 'Thresholds', 'IntegrityLimits', 'Verdict', 'Integrity']

OK, WARN, ERROR = 0, 1, 2
#: nats: a bound is not taken closer than the rounding of the sums it compares.
_ROUNDING = 1e-9


def _chi_square_limit(alpha, dof):
    """
    Return the upper ``alpha`` quantile of chi-square with ``dof`` degrees of freedom.

    Computed with scipy.special: a per-frame cost, where scipy.stats' generic machinery is
    ten times slower.
    """
    return 2.0 * gammainccinv(0.5 * np.asarray(dof, dtype=float), alpha)


def _binomial_tail(count, trials, fraction):
    """P(K >= count) for K ~ Binomial(trials, fraction); 1 where count is 0."""
    count = np.asarray(count, dtype=float)
    trials = np.asarray(trials, dtype=float)
    safe = np.maximum(count, 1.0)
    tail = betainc(safe, np.maximum(trials - safe + 1.0, 1e-300), fraction)
    return np.where(count > 0, np.where(count <= trials, tail, 0.0), 1.0)


def _excess_tail(total, count, gamma):
    """P(S >= total) for S the sum of ``count`` exponential excesses of mean ``gamma``."""
    count = np.asarray(count, dtype=float)
    tail = gammaincc(np.maximum(count, 1.0), np.maximum(total, 0.0) / gamma)
    return np.where(count > 0, tail, 1.0)


def _explained_otherwise(loss, excess, measured):
    """
    Return which measured links a ``LinkLoss`` takes for blocked, and which for outliers.

    Whichever is likelier, where line of sight is less likely than the two together.
    ``excess`` in sigmas, NaN where not ``measured``; two boolean arrays shaped like it.
    """
    if not measured.any():
        return measured.copy(), measured.copy()
    nlos, outlier = loss.posteriors(_zero_nan(excess))
    other = measured & (nlos + outlier > 0.5)
    return other & (nlos >= outlier), other & (nlos < outlier)


def _zero_nan(values):
    """Return a copy with NaN as 0 (the measured mask is kept aside)."""
    return np.where(np.isnan(values), 0.0, values)


def _check_positive(instance):
    for item in fields(instance):
        value = getattr(instance, item.name)
        if not (isinstance(value, (int, float, np.floating, np.integer))
                and math.isfinite(value) and value > 0):
            raise ValueError(f'{item.name}: must be a finite number > 0, got {value!r}')


@dataclass(frozen=True)
class Thresholds:
    """
    Limits of a good estimate, metres: above ``*_error`` ERROR, else above ``*_warn`` WARN.

    A ``*_warn`` above its ``*_error`` is allowed and means that quantity never warns: a
    pair is not required to be ordered, so ``ros2 param load``, which sets one parameter at
    a time in the file's order, reaches any pair a start-up could.
    """

    arm_length_warn: float = 0.05       #: worst section-length error
    arm_length_error: float = 0.5
    residual_warn: float = 0.5          #: range residual RMS
    residual_error: float = 2.0
    predicted_rmse_warn: float = 1.0    #: predicted RMSE of the joints, biases included
    predicted_rmse_error: float = 2.0

    def __post_init__(self):
        _check_positive(self)


@dataclass(frozen=True)
class IntegrityLimits:
    """
    How the consistency and observability checks decide.

    Attributes
    ----------
    false_alarm : float
        Probability that a frame consistent with the noise fails one residual test.
    ambiguity_odds : float
        Another position of a joint is ruled out when it is this many times less likely
        than the estimate's, given the frame's ranges.
    ambiguity_distance : float
        Metres; alternatives closer to the estimate than this, or than three times the
        joint's predicted standard deviation, do not matter.
    max_angular_rate : float
        Radians per second that neither the slew nor any section's pitch exceeds: how far
        each joint can have moved since the last accepted posture rules out alternatives
        and jumps (:meth:`Integrity.reach`). Hydraulic booms turn at up to about 0.2 rad/s.
    frame_period : float
        Seconds between frames when no stamps are given.

    """

    false_alarm: float = 1e-4
    ambiguity_odds: float = 1000.0
    ambiguity_distance: float = 1.0
    max_angular_rate: float = 0.35
    frame_period: float = 0.1

    def __post_init__(self):
        _check_positive(self)
        if not self.false_alarm < 0.5:
            raise ValueError(f'false_alarm: must be < 0.5, got {self.false_alarm}')
        if not self.ambiguity_odds > 1:
            raise ValueError(f'ambiguity_odds: must be > 1, got {self.ambiguity_odds}')


@dataclass
class Verdict:
    """
    The integrity of one estimate.

    Attributes
    ----------
    level : int
        OK, WARN or ERROR; ERROR is never published.
    status : str
        ``"ok"``, or why the posture is not published: ``"inconsistent"`` (residuals the
        noise cannot explain), ``"ambiguous"`` (a joint could fold), ``"unobservable"``
        (infinite or too large predicted uncertainty), ``"implausible"`` (below ground,
        wrong section lengths, or a jump faster than the boom moves).
    message : str
        One line for a person.
    values : dict
        The statistics behind it (for diagnostics).
    angles : tuple (float, ndarray (p,)), optional
        The estimate's slew and pitches, radians, as judged.
    los_rows : ndarray, shape (n, p + 1), optional
        The Jacobian in psi of the estimate's line-of-sight tag-anchor ranges (row-major
        over the links kept), unscaled, for the bias learner; None when not computed (a
        method not held to the chain).
    likelier : ndarray, shape (p, 3), optional
        The estimate with the joint of the likeliest rival position (``rival_margin``)
        moved there, the others kept, metres: where a solve may find a fit the frame
        prefers; None without a rival position.

    """

    level: int
    status: str
    message: str
    values: dict = field(default_factory=dict)
    angles: tuple = field(default=None, repr=False, compare=False)
    los_rows: np.ndarray = field(default=None, repr=False, compare=False)
    likelier: np.ndarray = field(default=None, repr=False, compare=False)

    @property
    def valid(self):
        """Whether the posture may be published."""
        return self.level < ERROR

    @property
    def lost(self):
        """Whether a fresh (cold) solve of the frame could do better than this estimate."""
        return self.status in ('inconsistent', 'implausible')

    @property
    def outweighed(self):
        """
        Whether the frame is ambiguous with a joint's rival position likelier than its own.

        A fit in the wrong basin: a search may find the likelier one and decide the frame.
        """
        return self.status == 'ambiguous' and self.values.get('rival_margin', np.inf) < 0.0


class Integrity:
    """
    Judges estimated postures for one boom and one noise model.

    Parameters
    ----------
    model : BoomModel
    noise : SensorNoise
        What the estimator is told about the measurement noise.
    nlos : NlosMixture
        The judge's range model: the prior fraction of blocked links, their mean excess,
        and the share of outliers (``NlosMixture.judged``, learned or the prior).
    eta : float
        Multiplicative range noise: a range r has sigma ``sqrt(sigma^2 + (eta r)^2)``.
    lowest_joint : float
        No joint is below this height, metres.
    limits : IntegrityLimits
    thresholds : Thresholds
    bias : RangeBiasPrior
        What is not known of the ranges' biases. Each link's own part is, within one
        frame, another independent error of each range: it adds to the range sigma of
        every check (:meth:`link_sigma`). The part common to all links moves a fit in a
        direction its residuals barely see: it adds to each joint's predicted standard
        deviation (``joint_std``, ``predicted_rmse``, judged by the observability
        thresholds) and to the turn a section may make between frames; the checks of
        ambiguity and the reach leave it out (a bias constant over frames neither folds a
        joint nor moves it). So does what a link the others barely check could hide
        (``uncontrolled_covariance``), for the methods that hold the chain.

    """

    #: Levenberg–Marquardt trial steps of each separation fit (:meth:`separated`).
    SEPARATION_ROUNDS = 8
    #: Assessments kept for a second judgement of the same estimate (:meth:`_assessed`).
    ASSESSMENTS_KEPT = 2

    def __init__(self, model, noise, nlos, eta=0.0, lowest_joint=-0.5,
                 limits=IntegrityLimits(), thresholds=Thresholds(), bias=RangeBiasPrior()):
        self.model = model
        self.bias = bias
        #: Covariance (2, 2) of the common bias's offset and slope still unknown: the
        #: prior's, or less once the estimator has learned it (``core.bias_learning``).
        self.common_covariance = bias.common_covariance()
        self.noise = noise
        self.nlos = nlos
        self.eta = float(eta)
        self.lowest_joint = float(lowest_joint)
        self.limits = limits
        self.thresholds = thresholds
        # The mixture's per-link constants, bound once where the sigmas are fixed.
        fixed = np.ndim(noise.range_sigma) == 0 and not self.eta and np.ndim(bias.link_std) == 0
        self._link_loss = nlos.bind(np.hypot(float(noise.range_sigma), bias.link_std)) \
            if fixed else None
        self._tag_loss = nlos.bind(np.asarray(noise.tag_sigma, float))
        self._planes = _mirror_planes(model)
        # The likelihood's peaks for the separation fits: the chain's loss, this mixture.
        self._peaks = ChainMethod(model, nlos_fraction=nlos.fraction, nlos_gamma=nlos.gamma,
                                  lowest_joint=lowest_joint)
        self._assessments = []          # (_AssessmentKey, _Assessment), the latest first
        self._link_sigma = (None, None, None)   # (Measurements, link_sigma, noise with it)

    # -- the pieces -----------------------------------------------------------------------
    def link_sigma(self, measurements):
        """
        Return the standard deviation of each tag-anchor range (p, m), metres (read-only).

        A frame's checks ask for it several times: the last frame's is kept.
        """
        if self._link_sigma[0] is not measurements:
            sigma = np.broadcast_to(np.asarray(self.noise.range_sigma, dtype=float),
                                    measurements.ranges.shape)
            noise = self.noise
            if self.eta or np.any(self.bias.link_std):
                sigma = np.hypot(sigma, self.eta * np.nan_to_num(measurements.ranges))
                sigma = np.hypot(sigma, self.bias.link_std)
                noise = replace(noise, range_sigma=sigma)
            sigma.flags.writeable = False
            self._link_sigma = (measurements, sigma, noise)
        return self._link_sigma[1]

    def _link_noise(self, measurements):
        """Return :attr:`noise` with :meth:`link_sigma` as the ranges' sigma (scalar or (p, m))."""
        self.link_sigma(measurements)
        return self._link_sigma[2]

    def _excess(self, joints, measurements):
        """Range excesses in sigmas: tag-anchor (p, m) and tag-tag (p, p), NaN unmeasured."""
        predicted = self.model.ranges(joints)
        links = (measurements.ranges - predicted) / self.link_sigma(measurements)
        between = norms(joints[:, None] - joints[None, :])
        tag_links = (measurements.tag_ranges - between) / self.noise.tag_sigma
        return links, tag_links

    def _bound_loss(self, measurements):
        """Return the NLOS mixture bound to the frame's link sigmas (``LinkLoss``)."""
        if self._link_loss is not None:
            return self._link_loss
        return self.nlos.bind(self.link_sigma(measurements))

    def _joint_cost(self, which, positions, measurements, joints, slew):
        """
        Loss of what sees joint ``which[i]`` if it were at ``positions[i]`` (n, 3).

        Its tag's ranges (NLOS mixture), its tag-tag ranges, and the inclinometers of the
        two sections it ends and starts, the other joints staying where they are. Shape (n,).
        """
        total = self._bound_loss(measurements).at_points(positions, measurements.ranges,
                                                         self.model.anchors, tags=which)
        # Sensors the frame lacks would add zeros: skipped (most frames are ranges only).
        if np.isfinite(measurements.tag_ranges).any():
            total = self._add_tag_cost(total, which, positions, measurements, joints)
        if np.isfinite(measurements.pitches).any():
            total = self._add_pitch_cost(total, which, positions, measurements, joints, slew)
        return total

    def _add_tag_cost(self, total, which, positions, measurements, joints):
        """Return ``total`` (n,) plus the tag-tag ranges' share of :meth:`_joint_cost`."""
        p = self.model.n_sections
        gaps = norms(positions[:, None, :] - joints[None, :, :])   # (n, p)
        for measured in (measurements.tag_ranges[which], measurements.tag_ranges[:, which].T):
            seen = np.isfinite(measured) & (np.arange(p) != which[:, None])
            error = np.where(seen, (measured - gaps) / self.noise.tag_sigma, 0.0)
            total = total + 0.5 * np.sum(error ** 2, axis=1)
        return total

    def _add_pitch_cost(self, total, which, positions, measurements, joints, slew):
        """Return ``total`` (n,) plus the inclinometers' share of :meth:`_joint_cost`."""
        p = self.model.n_sections
        along = np.array([np.cos(slew), np.sin(slew), 0.0])
        chain = np.vstack([self.model.pivot(slew), joints, joints[-1:]])
        for section, steps in ((which, positions - chain[which]),
                               (which + 1, chain[which + 2] - positions)):
            inside = section < p
            measured = measurements.pitches[np.minimum(section, p - 1)]
            seen = inside & np.isfinite(measured)
            error = wrap_angle(np.arctan2(steps[:, 2], steps @ along) - _zero_nan(measured))
            total = total + np.where(seen, 0.5 * (error / self.noise.pitch_sigma) ** 2, 0.0)
        return total

    def consistency(self, joints, measurements, fitted_dof=None):
        """
        Chi-square and binomial tests of the residuals; (failures, values, kept links).

        ``fitted_dof``: how many parameters the estimate spent on the frame, which its
        residuals then lack: the chain's p + 1 angles by default (and where not finite),
        3 per joint for a method that places each joint on its own (2 with its arm length
        held), fewer for a tracker whose prediction supplied part (its own count). The
        chi-square's degrees of freedom are the links kept less these, at least 1.

        Returns
        -------
        failures : list of str
        values : dict
        kept : (ndarray, ndarray)
            The tag-anchor (p, m) and tag-tag (p, p) links taken as line-of-sight.

        """
        alpha = self.limits.false_alarm
        links, tag_links = self._excess(joints, measurements)
        measured, tag_measured = np.isfinite(links), np.isfinite(tag_links)
        sigma = self.link_sigma(measurements)
        loss = self._bound_loss(measurements)
        blocked, outlying = _explained_otherwise(loss, links, measured)
        tag_blocked, tag_outlying = _explained_otherwise(self._tag_loss, tag_links, tag_measured)
        kept = measured & ~blocked & ~outlying
        tag_kept = tag_measured & ~tag_blocked & ~tag_outlying
        p = self.model.n_sections
        statistic = float(np.sum(links[kept] ** 2) + np.sum(tag_links[tag_kept] ** 2))
        spent = fitted_dof if fitted_dof is not None and math.isfinite(fitted_dof) else p + 1
        dof = max(int(kept.sum() + tag_kept.sum()) - spent, 1)
        limit = float(_chi_square_limit(alpha, dof))
        n_links = int(measured.sum() + tag_measured.sum())
        n_blocked = int(blocked.sum() + tag_blocked.sum())
        failures = []
        if statistic > limit:
            failures.append(f'range residuals chi-square {statistic:.1f} > {limit:.1f}')
        n_outlying = int(outlying.sum() + tag_outlying.sum())
        # With no link set aside every tail below is 1 (most frames): not computed.
        if n_blocked and _binomial_tail(n_blocked, n_links, self.nlos.fraction) < alpha:
            failures.append(f'{n_blocked} of {n_links} links look blocked')
        if n_outlying and _binomial_tail(n_outlying, n_links, self.nlos.outliers) < alpha:
            failures.append(f'{n_outlying} of {n_links} ranges look like outliers')
        # Blocked links: as many, and as long, as the NLOS prior makes believable.
        metres = np.where(blocked, _zero_nan(links) * sigma, 0.0)
        if n_blocked:
            tag_metres = np.where(tag_blocked, _zero_nan(tag_links) * self.noise.tag_sigma, 0.0)
            total = float(metres.sum() + tag_metres.sum())
            if _excess_tail(total, n_blocked, self.nlos.gamma) < alpha:
                failures.append(f'blocked links {total:.1f} m too long in all')
        tag_statistic = np.sum(np.where(kept, links, 0.0) ** 2, axis=1)
        tag_limit = _chi_square_limit(alpha / p, np.maximum(kept.sum(axis=1), 1))
        bad = tag_statistic > tag_limit
        if blocked.any() or outlying.any():
            blocked_count = blocked.sum(axis=1)
            tag_tail = np.minimum.reduce([
                _binomial_tail(blocked_count, measured.sum(axis=1), self.nlos.fraction),
                _excess_tail(metres.sum(axis=1), blocked_count, self.nlos.gamma),
                _binomial_tail(outlying.sum(axis=1), measured.sum(axis=1),
                               self.nlos.outliers)])
            bad |= tag_tail < alpha / p
        bad_tags = np.flatnonzero(bad)
        if bad_tags.size:
            failures.append('ranges of joint(s) ' + ', '.join(str(k + 1) for k in bad_tags)
                            + ' not explained by the noise')
        los_metres = (links * sigma)[kept]
        values = {'chi_square': statistic, 'chi_square_limit': limit, 'chi_square_dof': dof,
                  'links': n_links,
                  'nlos_links': blocked, 'nlos_tag_links': tag_blocked,
                  'outlier_links': outlying, 'outlier_tag_links': tag_outlying,
                  'tag_chi_square': tag_statistic,
                  'los_residual_rms': float(np.sqrt(np.mean(los_metres ** 2)))
                  if los_metres.size else 0.0}
        return failures, values, (kept, tag_kept)

    def bound(self, joints, measurements, kept, angles):
        """
        Cramér–Rao bound at the estimate from the line-of-sight links and the angles.

        ``angles``: the estimate's (slew, pitches), radians. The frame's own: a motion
        model's prediction is not trusted to make a posture valid (its process noise is
        itself a guess).
        """
        return self.bounds(joints, measurements, kept, angles)[0]

    def bounds(self, joints, measurements, kept, angles):
        """
        Return :meth:`bound`, and that bound with the unknown common range bias added.

        Both count each link's own bias in its sigma; the second adds what the links the
        others barely check could hide (``uncontrolled_covariance``) too, and is the first
        when neither adds anything or the first is infinite.
        """
        return self._bounds(joints, measurements, kept, angles)[:2]

    def _bounds(self, joints, measurements, kept, angles):
        """Return :meth:`bounds`' two and the unscaled Jacobian rows (n, p + 1) of the links."""
        ranges, tag_ranges = kept
        used = Measurements(np.where(ranges, measurements.ranges, np.nan),
                            np.where(tag_ranges, measurements.tag_ranges, np.nan),
                            measurements.pitches, measurements.slew)
        residuals = Residuals(self.model, used, self._link_noise(measurements))
        common = None
        if self.common_covariance.any():
            tags, anchors = np.nonzero(residuals.link_mask)
            directions = self.anchor_directions(joints)[tags, anchors]
            common = (bias_design(residuals.measured[:tags.size], directions, anchors,
                                  self.bias.moving), self.common_covariance)
        psi = np.concatenate([[angles[0]], angles[1]])
        return frame_bounds(self.model, residuals, psi, common)

    def reach(self, reference, elapsed, reference_std):
        """
        How far each joint can have moved in ``elapsed`` seconds from ``reference``.

        Every angle turning at ``max_angular_rate`` moves joint k by at most the rate times
        its lever: its distance from the slew axis, plus its distance from each joint at or
        inside it (pivot included). Plus three times the reference's own standard
        deviation ``reference_std`` (p,). Shape (p,), metres.
        """
        chain = np.vstack([self.model.pivot_of(reference), reference])
        radius = norms(reference[:, :2] - self.model.base[:2])
        inside = np.tril(norms(chain[:, None] - chain[None, :]), k=-1)   # joint k: row k + 1
        levers = inside[1:].sum(axis=1)
        return (self.limits.max_angular_rate * elapsed * (radius + levers)
                + 3.0 * np.asarray(reference_std))

    def anchor_directions(self, joints):
        """Return unit vectors (p, m, 3) from each anchor to each joint."""
        units = joints[:, None, :] - self.model.anchors
        return units / np.maximum(norms(units), 1e-12)[..., None]

    def point_bound(self, joints, measurements, kept, biased=False):
        """
        Per-joint standard deviations (p,) of joints located each from its own ranges.

        The bound of a method that does not hold the boom to its p + 1 angles (EPP1, EPP2,
        the per-tag baselines): each joint's 3-D Fisher information from its kept links;
        infinite for a joint with fewer than three, or with anchors on one line. With
        ``biased``, the bias common to all links is added, as in :meth:`bounds`.
        """
        units = self.anchor_directions(joints)
        weights = np.where(kept[0], self.link_sigma(measurements) ** -2.0, 0.0)
        information = np.einsum('km,kmi,kmj->kij', weights, units, units)
        std = np.full(self.model.n_sections, np.inf)
        for k, matrix in enumerate(information):
            values, vectors = np.linalg.eigh(matrix)
            if values[0] > 1e-12 * max(values[-1], 1e-300):
                covariance = (vectors / values) @ vectors.T
                if biased and self.common_covariance.any():
                    design = bias_design(np.nan_to_num(measurements.ranges[k]), units[k],
                                         np.arange(self.model.n_anchors), self.bias.moving)
                    through = covariance @ (units[k] * weights[k][:, None]).T @ design
                    covariance = covariance + through @ self.common_covariance @ through.T
                std[k] = math.sqrt(np.trace(covariance))
        return std

    def separated(self, joints, measurements, kept):
        """
        Fit the frame again without each tag's ranges in turn, when links were set aside.

        Under blocked links the likelihood can peak where other links are the blocked
        ones: a fit that took a tag's NLOS excess for line of sight is metres off with
        residuals that look clear. Solution separation, as receiver autonomous integrity
        monitoring does it, leaves each tag's ranges out in turn and lets the rest say
        where the boom is, from ``joints`` (p, 3); :meth:`judge` weighs these fits with
        all the ranges, as rivals. Only when the consistency checks set a tag-anchor link
        aside (``kept`` as :meth:`consistency` returns it): with every link clear the
        likelihood peaks once near the estimate, up to the folds and mirrors weighed anyway.
        The fits use the tag-anchor ranges, all side by side
        (:meth:`ChainMethod.refine_links`); the rivals are weighed on everything measured.
        Returns a list of postures (p, 3), metres.
        """
        ranges = measurements.ranges
        measured = np.isfinite(ranges)
        if not (measured & ~kept[0]).any():
            return []
        heard = np.flatnonzero(measured.any(axis=1))
        masks = np.ones((heard.size,) + ranges.shape, dtype=bool)
        masks[np.arange(heard.size), heard] = False
        postures = self._peaks.refine_links(joints, ranges, self.link_sigma(measurements),
                                            masks, self.SEPARATION_ROUNDS)
        return [posture for posture in postures if np.all(np.isfinite(posture))]

    def _near(self, joint_std):
        """
        Per joint, metres: alternatives closer than this do not matter (p,).

        ``ambiguity_distance``, or where the joint's own Gaussian posterior (its predicted
        std) stops putting positions within ``ambiguity_odds`` of the estimate,
        ``sqrt(2 ln odds)`` std (3.7 at 1000:1), if further: nearer, the std already says
        the joint may be there, and calling its own tail a rival refused frames the std
        covered.
        """
        tail = math.sqrt(2.0 * math.log(self.limits.ambiguity_odds))
        return np.maximum(self.limits.ambiguity_distance,
                          tail * np.nan_to_num(joint_std, posinf=0.0))

    def fold_spread(self, joints, measurements, slew):
        """
        Return how far each inner joint's fold lies when about as likely, metres (p,).

        A fold within ``ambiguity_distance`` is not ambiguous now, but a joint no range
        pins (a silent tag) keeps its fold from frame to frame, and the boom can bend the
        two folds apart within any one frame's reach: the reference posture must allow the
        joint at either (:meth:`reach`), or time would rule out the right one.
        """
        positions = fold_alternatives(self.model, joints)                   # (p - 1, 3)
        which = np.arange(self.model.n_sections - 1)
        return self._spread(joints, positions, self._margins(joints, measurements, slew,
                                                             positions, which))

    def ambiguous_joints(self, joints, measurements, joint_std, slew, reach=None):
        """
        Joints (0-based) with another position about as likely, and one such position.

        A fold of an inner joint, or the tip at another pitch, counts when its ranges make
        it no more than ``ambiguity_odds`` times less likely than the estimate, when it is
        further than ``ambiguity_distance`` and the joint's own Gaussian tail (:meth:`_near`;
        ``joint_std`` (p,)) away, and, given how far each joint can have moved since the
        last accepted posture (``reach``: that posture and the distances, see
        :meth:`reach`), when it could have got there.
        """
        positions, which, keep = self._candidates(joints, joint_std, slew, reach)
        if not keep.any():
            return {}
        positions, which = positions[keep], which[keep]
        return self._found(positions, which,
                           self._margins(joints, measurements, slew, positions, which))

    def _joint_rivals(self, joints, measurements, joint_std, slew, reach):
        """
        Return :meth:`fold_spread`, :meth:`ambiguous_joints` and the likeliest rival.

        The folds :meth:`fold_spread` weighs are the first of :meth:`ambiguous_joints`'
        candidates; each joint's cost is then computed once, not twice. The likeliest of
        the candidates far enough and within reach is returned as its margin, how much
        less likely it is than the estimate's joint in nats (negative: likelier), and its
        (joint, position (3,)); inf and None without one.
        """
        p = self.model.n_sections
        positions, which, keep = self._candidates(joints, joint_std, slew, reach)
        scored = keep | (np.arange(len(which)) < p - 1)           # every fold, and the kept
        margin = self._margins(joints, measurements, slew, positions[scored], which[scored])
        spread = self._spread(joints, positions[:p - 1], margin[:p - 1])
        counted = keep[scored]
        found = self._found(positions[scored][counted], which[scored][counted],
                            margin[counted])
        if not counted.any():
            return spread, found, np.inf, None
        best = np.argmin(margin[counted])
        return (spread, found, float(margin[counted][best]),
                (int(which[scored][counted][best]), positions[scored][counted][best]))

    def _candidates(self, joints, joint_std, slew, reach):
        """
        Return the other positions :meth:`ambiguous_joints` weighs, and which count.

        Each inner joint folded, then the tip's circle: positions (n, 3), metres, their
        joints (n,) and whether each is far enough and within ``reach`` (n,).
        """
        near = self._near(joint_std)
        p = self.model.n_sections
        tip = self._tip_circle(joints, slew)
        positions = np.vstack([fold_alternatives(self.model, joints), tip])
        which = np.concatenate([np.arange(p - 1), np.full(len(tip), p - 1)])
        keep = norms(positions - joints[which]) > near[which]
        if reach is not None:
            keep &= _within_reach(reach, positions, which)
        return positions, which, keep

    def _margins(self, joints, measurements, slew, positions, which):
        """Return how much costlier joint ``which[i]`` is at ``positions[i]``, shape (n,)."""
        p = self.model.n_sections
        costs = self._joint_cost(np.concatenate([np.arange(p), which]),
                                 np.vstack([joints, positions]),
                                 measurements, joints, slew)
        return costs[p:] - costs[which]

    def _spread(self, joints, folds, margin):
        """Return :meth:`fold_spread` from the folds (p - 1, 3) and their margins (p - 1,)."""
        which = np.arange(len(folds))
        close = margin < math.log(self.limits.ambiguity_odds)
        spread = np.zeros(self.model.n_sections)
        spread[which[close]] = norms(folds[close] - joints[which[close]])
        return spread

    def _found(self, positions, which, margin):
        """Return :meth:`ambiguous_joints`' joints and their likeliest other positions."""
        found = {}
        for k in np.unique(which[margin < math.log(self.limits.ambiguity_odds)]):
            rivals = np.flatnonzero(which == k)
            found[int(k)] = positions[rivals[np.argmin(margin[rivals])]]
        return found

    def mirrors(self, joints, slew):
        """
        Return the whole boom reflected where the anchors cannot tell it from its image.

        Across the vertical plane through the slew axis that best fits the anchors (a
        valid posture, slew mirrored), and across the plane that best fits the anchors in
        space (kept when it stays above ``lowest_joint``). Anchors spread in every
        direction tell both apart; anchors near one line or plane do not. Shape (k, p, 3).
        """
        centre, across, mean, normal = self._planes
        mirrored = [joints - 2.0 * ((joints - centre) @ across)[:, None] * across]
        image = joints - 2.0 * ((joints - mean) @ normal)[:, None] * normal
        if image[:, 2].min() >= self.lowest_joint:
            mirrored.append(image)
        return np.array(mirrored)

    def posture_cost(self, postures, measurements, scored=None):
        """
        Loss of every measurement of the frame at each posture (n, p, 3): shape (n,).

        ``scored`` (p, m) bool: the tag-anchor ranges counted, by default all.
        """
        ranges = measurements.ranges if scored is None else \
            np.where(scored, measurements.ranges, np.nan)
        cost = self._bound_loss(measurements).at_points(postures, ranges,
                                                        self.model.anchors).sum(axis=1)
        tag_valid = np.isfinite(measurements.tag_ranges)
        if tag_valid.any():
            gaps = norms(postures[:, :, None, :] - postures[:, None, :, :])
            error = np.where(tag_valid, (measurements.tag_ranges - gaps)
                             / self.noise.tag_sigma, 0.0)
            cost = cost + 0.5 * np.sum(error ** 2, axis=(1, 2))
        angles_seen = np.isfinite(measurements.pitches).any() or np.isfinite(measurements.slew)
        for i, posture in enumerate(postures if angles_seen else []):
            slew, pitches = angles_from_joints(self.model, posture)
            pitch_error = wrap_angle(pitches - _zero_nan(measurements.pitches))
            cost[i] += 0.5 * np.sum(np.where(np.isfinite(measurements.pitches),
                                             pitch_error / self.noise.pitch_sigma, 0.0) ** 2)
            if np.isfinite(measurements.slew):
                cost[i] += 0.5 * (wrap_angle(slew - measurements.slew)
                                  / self.noise.slew_sigma) ** 2
        return cost

    def ambiguous_postures(self, joints, measurements, joint_std, slew, reach=None,
                           alternatives=()):
        """
        Joints (0-based) that another whole posture, about as likely, puts elsewhere.

        The candidates are the boom's :meth:`mirrors` and the method's own
        ``alternatives`` (other fits its search found, (p, 3) each); the rules are those of
        :meth:`ambiguous_joints`, and with a ``reach`` every joint must be within it, or the
        frame must make the posture ``ambiguity_odds`` times likelier than the estimate.
        Beyond the reach of the last accepted posture, a posture the frame prefers that
        strongly says that the reference (a warm fit drifted with what it published) or
        the frame is wrong, not that the estimate is right.
        """
        candidates = [self.mirrors(joints, slew)]
        candidates += [np.asarray(a, dtype=float)[None] for a in alternatives]
        candidates = np.concatenate(candidates)
        near = self._near(joint_std)
        far = norms(candidates - joints) > near                               # (n, p)
        keep = far.any(axis=1)
        if not keep.any():
            return set()
        costs = self.posture_cost(np.concatenate([joints[None], candidates[keep]]),
                                  measurements)
        odds = math.log(self.limits.ambiguity_odds)
        rivals = costs[1:] - costs[0] < odds
        if reach is not None:
            within = np.all(_within_reach(reach, candidates[keep]), axis=1)
            rivals &= within | (costs[1:] - costs[0] < -odds)
        return set(np.flatnonzero(far[keep][rivals].any(axis=0)).tolist())

    def _tip_circle(self, joints, slew):
        """Positions of the tip at pitches all round its hinge, in the boom's plane."""
        hinge = joints[-2] if self.model.n_sections > 1 else self.model.pivot(slew)
        return tip_circle(self.model, hinge, slew)[1]

    #: Bends tried of each joint turned round its hinge, and the most outer joints turned.
    TAIL_BENDS = 2
    TAIL_JOINTS = 3

    def tail_bends(self, joints, measurements, slew, near):
        """
        Return the boom with its outer joints at other bends their ranges favour (k, p, 3).

        The judge's other candidates move one joint, or the whole boom: where the outer
        joints are barely seen (a long boom folded low, its anchors 30-40 m away and
        within 4 m of one height) the last two or three sections can fit other bends
        about as well, each joint metres off. From each of the last ``TAIL_JOINTS`` joints
        but the tip: it is turned all round its hinge, and at the ``TAIL_BENDS`` lowest
        minima of its own ranges' loss further than ``near`` (p,) from where it is, the
        next joint round it, kept at its own ``TAIL_BENDS`` lowest, and so on to the tip:
        the postures so placed, the joints within where they are. A bend is not followed
        where its ranges and the least the joints beyond it could cost (``LinkLoss.floor``)
        already make it ``ambiguity_odds`` times less likely than the estimate.
        """
        return self._tail_bends(joints, measurements, slew, near,
                                self.posture_cost(joints[None], measurements)[0])

    def _tail_bends(self, joints, measurements, slew, near, cost):
        """Return :meth:`tail_bends`, ``cost`` the estimate's :meth:`posture_cost`."""
        p = self.model.n_sections
        if p < 2:
            return np.zeros((0, p, 3))
        loss = self._bound_loss(measurements)
        own = loss.at_points(joints[None], measurements.ranges, self.model.anchors)[0]
        floors = np.sum(np.where(np.isfinite(measurements.ranges), loss.floor, 0.0), axis=1)
        # The estimate's other terms (tag ranges, angles): a tail's may all be 0.
        allowed = math.log(self.limits.ambiguity_odds) + _ROUNDING + cost - own.sum()
        tails = [self._bent_from(first, joints, measurements, slew, near, loss, own, floors,
                                 allowed)
                 for first in range(p - 2, max(p - 1 - self.TAIL_JOINTS, -1), -1)]
        return np.concatenate(tails) if tails else np.zeros((0, p, 3))

    def _bent_from(self, first, joints, measurements, slew, near, loss, own, floors,
                   allowed):
        """
        Return :meth:`tail_bends`' postures turned from joint ``first`` out (k, p, 3).

        ``own`` and ``floors`` (p,): each joint's ranges' cost at ``joints`` and the least
        it could be anywhere; ``allowed``: nats, the most the joints turned may cost more
        than at ``joints``, less what the joints beyond could cost less.
        """
        postures, spent = np.array(joints, dtype=float)[None], np.zeros(1)
        for k in range(first, self.model.n_sections):
            hinges = postures[:, k - 1] if k else self.model.pivot(slew)[None]
            ends = tip_circle(self.model, hinges, slew, section=k)[1]     # (n, pitches, 3)
            costs = loss.at_points(ends.reshape(-1, 3), measurements.ranges,
                                   self.model.anchors, tags=np.full(ends[..., 0].size, k))
            costs = costs.reshape(ends.shape[:2])
            away = norms(ends - joints[k]) > near[k] if k == first else \
                np.ones(ends.shape[:2], dtype=bool)
            rows, bends = np.array([(i, j) for i in range(len(postures))
                                    for j in tip_minima(costs[i], away[i])[:self.TAIL_BENDS]],
                                   dtype=int).reshape(-1, 2).T
            spent = spent[rows] + costs[rows, bends] - own[k]
            hopeful = spent - np.sum(own[k + 1:] - floors[k + 1:]) <= allowed
            postures = postures[rows[hopeful]]
            postures[:, k] = ends[rows[hopeful], bends[hopeful]]
            spent = spent[hopeful]
            if not len(postures):
                break
        return postures

    def _tail_rivals(self, joints, measurements, joint_std, slew, reach):
        """
        Return the likeliest of the :meth:`tail_bends` within ``reach``, and it as found.

        Its margin (how much less likely it is than ``joints`` on the frame, nats;
        negative: likelier) and posture, or inf and None; ``found`` maps each joint it
        turned to its position there where the margin is within the ambiguity odds.
        """
        cost = self.posture_cost(joints[None], measurements)[0]
        tails = self._tail_bends(joints, measurements, slew, self._near(joint_std), cost)
        turned = np.any(tails != joints, axis=2)                            # (k, p)
        if reach is not None and len(tails):
            within = np.all(_within_reach(reach, tails) | ~turned, axis=1)
            tails, turned = tails[within], turned[within]
        if not len(tails):
            return {}, np.inf, None
        margins = self.posture_cost(tails, measurements) - cost
        best = int(np.argmin(margins))
        found = {int(k): tails[best, k] for k in np.flatnonzero(turned[best])} \
            if margins[best] < math.log(self.limits.ambiguity_odds) else {}
        return found, float(margins[best]), tails[best]

    # -- the verdict ----------------------------------------------------------------------
    def judge(self, joints, measurements, reference=None, elapsed=None, reference_std=None,
              alternatives=(), chain=True, timed_joints=None, rivals=(),
              reference_turn_std=None, fitted_dof=None):
        """
        Return the :class:`Verdict` on an estimate of one frame.

        Parameters
        ----------
        joints : ndarray, shape (p, 3)
            The estimate, metres.
        measurements : Measurements
            The frame it was estimated from.
        reference : ndarray, shape (p, 3), optional
            The last accepted posture, ``elapsed`` seconds before, with its predicted
            joint standard deviations ``reference_std`` (p,): what the boom could have
            reached since rules out alternatives and jumps.
        elapsed : float, optional
            Seconds since ``reference``.
        reference_std : ndarray, shape (p,), optional
            Predicted standard deviation of each of ``reference``'s joints, metres.
        alternatives : sequence of ndarray, shape (p, 3)
            Other postures the method found that fit the frame (its search's runners-up).
        chain : bool
            Whether the method holds the boom to its p + 1 angles (the chain's bound is
            then its uncertainty); else each joint's own 3-D bound is
            (:meth:`point_bound`).
        timed_joints : ndarray, shape (p, 3), optional
            Each tag's joint when it ranged (TDMA slots on a moving boom), for the
            residuals; ``joints`` by default.
        rivals : sequence of ndarray, shape (p, 3)
            Postures the method itself holds about as likely, all frames considered (a
            tracker's fold hypotheses): a joint further than ``ambiguity_distance`` from
            one is ambiguous, whatever its own uncertainty.
        reference_turn_std : ndarray, shape (p,), optional
            Standard deviation of each of ``reference``'s sections' direction, radians
            (its verdict's ``reach_turn_std``); by default bounded by ``reference_std``.
        fitted_dof : float, optional
            Parameters the method spent on the frame (:meth:`consistency`); the chain's
            p + 1 angles by default.

        Returns
        -------
        Verdict

        """
        assessed = self._assessed(joints, measurements, reference, elapsed, reference_std,
                                  chain, timed_joints, reference_turn_std, fitted_dof)
        checks, values = list(assessed.checks), dict(assessed.values)
        alternatives = list(alternatives) + assessed.separated
        found, joint_std, seen, reach = (assessed.found, assessed.joint_std, assessed.seen,
                                         assessed.reach)
        angles, shift = assessed.angles, assessed.seen - joints
        ambiguous = set(found)
        ambiguous |= self.ambiguous_postures(seen, measurements, joint_std, angles[0], reach,
                                             [np.asarray(a) + shift for a in alternatives])
        for rival in rivals:
            far = norms(np.asarray(rival, dtype=float) - joints) > self.limits.ambiguity_distance
            ambiguous |= set(np.flatnonzero(far).tolist())
        values['ambiguous_joints'] = sorted(k + 1 for k in ambiguous)
        if ambiguous:
            checks.append((ERROR, 'ambiguous', 'joint(s) ' + ', '.join(
                str(k + 1) for k in sorted(ambiguous)) + ' could be elsewhere: another '
                'posture fits about as well'))
        verdict = _verdict(checks, values)
        verdict.angles, verdict.los_rows = angles, assessed.los_rows
        verdict.likelier = assessed.likelier
        return verdict

    def _assessed(self, joints, measurements, reference, elapsed, reference_std, chain,
                  timed_joints, reference_turn_std, fitted_dof):
        """
        Return :meth:`judge`'s :class:`_Assessment` of an estimate.

        All but its alternatives and rivals. A frame in doubt is judged again with the
        other fit as an alternative (``PostureEstimator``'s second opinion), the same
        estimate on the same frame: the last few assessments are kept and reused, not
        computed again. Besides the arguments, only ``common_covariance`` changes between
        judgements (the estimator's bias learner sets it) and is part of the key; the rest
        of this object is fixed once built.
        """
        key = _AssessmentKey.of(joints, measurements, reference, elapsed, reference_std,
                                chain, timed_joints, self.common_covariance,
                                reference_turn_std, fitted_dof)
        for known, assessment in self._assessments:
            if known == key:
                return assessment
        checks, values = [], {}             # (level, status, message), worst kept
        reach = None if reference is None else (
            reference, self.reach(reference, elapsed, reference_std))
        angles = angles_from_joints(self.model, joints)
        self._plausibility(joints, angles[0], reach, elapsed, checks, values)
        kept = self._consistency(joints if timed_joints is None else timed_joints,
                                 measurements, fitted_dof, checks, values)
        los_rows = None
        # Residuals larger than their noise say: the a-posteriori unit variance, never < 1.
        values['variance_factor'] = max(1.0, values['chi_square'] / values['chi_square_dof'])
        scale = math.sqrt(values['variance_factor'])
        if chain:
            random, total, los_rows = self._bounds(joints, measurements, kept, angles)
            joint_std, total_std = random.joint_std * scale, total.joint_std * scale
            turn_std = total.direction_std(angles[1]) * scale
        else:
            joint_std = self.point_bound(joints, measurements, kept) * scale
            total_std = self.point_bound(joints, measurements, kept, biased=True) * scale
            turn_std = self._direction_std(total_std)
        # Postures are weighed where each tag was when it ranged (a moving boom, TDMA).
        seen = np.array(joints if timed_joints is None else timed_joints, dtype=float)
        values['noise_rmse'] = float(np.sqrt(np.mean(joint_std ** 2)))
        self._observability(total_std, checks, values)
        if reference is not None:
            if reference_turn_std is None:
                reference_turn_std = self._direction_std(reference_std)
            self._turns(joints, turn_std, reference, reference_turn_std, elapsed, checks,
                        values)
        separated = []
        if chain and all(level < ERROR for level, _, _ in checks):
            separated = self.separated(joints, measurements, kept)
        spread, found, values['rival_margin'], likeliest = self._joint_rivals(
            seen, measurements, joint_std, angles[0], reach)
        likelier = None
        if likeliest is not None:           # the joint moved there, the others kept
            likelier = np.array(joints, dtype=float)
            likelier[likeliest[0]] += likeliest[1] - seen[likeliest[0]]
        tail_found, tail_margin, tail = self._tail_rivals(seen, measurements, joint_std,
                                                          angles[0], reach)
        found = {**tail_found, **found}
        if tail is not None and tail_margin < values['rival_margin']:
            values['rival_margin'] = tail_margin
            likelier = np.array(joints, dtype=float) + (tail - seen)   # the two moved
        values['reach_std'] = np.maximum(joint_std, spread)
        values['reach_turn_std'] = np.maximum(turn_std, self._direction_std(spread))
        assessment = _Assessment(tuple(checks), values, angles, los_rows, joint_std, seen,
                                 reach, separated, found, likelier)
        self._assessments = [(key, assessment)] + self._assessments[:self.ASSESSMENTS_KEPT - 1]
        return assessment

    def _consistency(self, joints, measurements, fitted_dof, checks, values):
        """Append the residual checks to ``checks``; return the links judged clear."""
        failures, found, kept = self.consistency(joints, measurements, fitted_dof)
        values.update(found)
        if failures:
            checks.append((ERROR, 'inconsistent', '; '.join(failures)))
        t = self.thresholds
        rms = values['los_residual_rms']
        if rms > t.residual_error:
            checks.append((ERROR, 'inconsistent', f'line-of-sight range residual {rms:.2f} m'))
        elif rms > t.residual_warn:
            checks.append((WARN, 'ok', f'line-of-sight range residual {rms:.2f} m'))
        return kept

    def _observability(self, joint_std, checks, values):
        """Append the predicted uncertainty against the thresholds to ``checks``."""
        t = self.thresholds
        rmse = float(np.sqrt(np.mean(joint_std ** 2)))
        values.update(predicted_rmse=rmse, joint_std=joint_std)
        if not math.isfinite(rmse) or rmse > t.predicted_rmse_error:
            checks.append((ERROR, 'unobservable', f'predicted RMSE {rmse:.2f} m'))
        elif rmse > t.predicted_rmse_warn:
            checks.append((WARN, 'ok', f'predicted RMSE {rmse:.2f} m'))

    def _across_plane(self, joints, slew):
        """Signed distances (p,) of the joints from the vertical plane of ``slew``."""
        pivot = self.model.pivot(slew)
        return (joints[:, :2] - pivot[:2]) @ np.array([-np.sin(slew), np.cos(slew)])

    def _plausibility(self, joints, slew, reach, elapsed, checks, values):
        """Ground, section lengths, the boom's plane and speed, appended to ``checks``."""
        t = self.thresholds
        lowest = float(joints[:, 2].min())
        if lowest < self.lowest_joint:
            checks.append((ERROR, 'implausible',
                           f'a joint {lowest:.2f} m high, below lowest_joint'))
        length_error = float(np.max(np.abs(self.model.section_lengths(joints)
                                           - self.model.arm_lengths)))
        if length_error > t.arm_length_error:
            checks.append((ERROR, 'implausible', f'a section {length_error:.2f} m off length'))
        elif length_error > t.arm_length_warn:
            checks.append((WARN, 'ok', f'a section {length_error:.3f} m off length'))
        # The boom is in one vertical plane through the slew axis (the paper's Feature II);
        # the 3-D methods do not impose it, and off it the ranges see little.
        off_plane = float(np.max(np.abs(self._across_plane(joints, slew))))
        values['off_plane'] = off_plane
        if off_plane > t.arm_length_error:
            checks.append((ERROR, 'implausible', f'a joint {off_plane:.2f} m off the boom plane'))
        elif off_plane > t.arm_length_warn:
            checks.append((WARN, 'ok', f'a joint {off_plane:.3f} m off the boom plane'))
        if reach is not None:
            moved = norms(joints - reach[0])
            values['moved'] = float(moved.max())
            jumped = np.flatnonzero(moved > reach[1])
            if jumped.size:
                checks.append((ERROR, 'implausible', f'joint {jumped[0] + 1} moved '
                               f'{moved[jumped[0]]:.1f} m in {elapsed:.2f} s'))

    def section_turns(self, joints, reference):
        """
        Return the angle (p,) each section's direction turned from ``reference`` to ``joints``.

        Radians, in [0, pi]: the slew and the section's pitch together, free of how the
        angles are written (a first section past vertical, a slew wrapped). Both (p, 3).
        """
        def steps(chain):
            return np.diff(np.vstack([self.model.pivot_of(chain), chain]), axis=0)
        now, then = steps(joints), steps(reference)
        return np.arctan2(norms(np.cross(now, then)), np.einsum('ki,ki->k', now, then))

    def _direction_std(self, joint_std):
        """
        Bound each section's direction std (p,), radians, by its end joints' stds (p,), metres.

        Their sum across the section's length: the most two joints' errors can turn it,
        however correlated (a method not held to the chain, or a joint's other fold).
        """
        ends = np.concatenate([[0.0], np.asarray(joint_std, dtype=float)])
        return (ends[:-1] + ends[1:]) / self.model.arm_lengths

    def _turns(self, joints, turn_std, reference, reference_turn_std, elapsed, checks,
               values):
        """
        Append a section that turned further than the boom can since ``reference``.

        Slew and pitch at ``max_angular_rate`` each turn a section by at most twice the
        rate times ``elapsed``; what either posture's directions are unsure of (stds (p,),
        radians) widens it by three standard deviations. This is the rate's own limit,
        where :meth:`reach` is a bound on each joint's distance that every angle at once
        allows: a tip turned over between frames, within that distance, stays out, and so
        does a joint whose tag's ranges are all outliers, moved metres in a frame to where
        two of them agree.
        """
        turned = self.section_turns(joints, reference)
        allowed = (2.0 * self.limits.max_angular_rate * elapsed
                   + 3.0 * np.hypot(turn_std, reference_turn_std))
        values['turned'] = float(np.max(turned))
        over = np.flatnonzero(turned > allowed)
        if over.size:
            checks.append((ERROR, 'implausible', f'section {over[0] + 1} turned '
                           f'{turned[over[0]]:.2f} rad in {elapsed:.2f} s'))


def _within_reach(reach, positions, joints=slice(None)):
    """
    Return whether each of ``positions`` (..., 3) is within ``reach`` of its joint.

    ``reach``: (reference (p, 3), distances (p,)), :meth:`Integrity.reach`'s; ``joints``:
    which joint each position is (indices, or a slice of the last axis but one).
    """
    return norms(positions - reach[0][joints]) <= reach[1][joints]


class _Assessment(NamedTuple):
    """What :meth:`Integrity.judge` finds of an estimate before its alternatives are weighed."""

    checks: tuple               #: (level, status, message) each
    values: dict                #: the statistics so far (:attr:`Verdict.values`)
    angles: tuple               #: (slew, pitches (p,)), radians
    los_rows: Optional[np.ndarray]      #: (n, p + 1), see :attr:`Verdict.los_rows`
    joint_std: np.ndarray       #: (p,) metres, without the common bias
    seen: np.ndarray            #: (p, 3) each joint where its tag ranged, metres
    reach: Optional[tuple]      #: (reference, distances (p,)) or None
    separated: list             #: the solution separation's postures, (p, 3) each
    found: dict                 #: joint -> a position about as likely, elsewhere
    likelier: Optional[np.ndarray]  #: (p, 3) the likeliest of those in place, or None


class _AssessmentKey:
    """What an assessment depends on: the frame (the object itself) and the arrays' bytes."""

    def __init__(self, measurements, *parts):
        self.measurements = measurements
        self.parts = tuple(part.tobytes() if isinstance(part, np.ndarray) else part
                           for part in parts)

    @classmethod
    def of(cls, joints, measurements, reference, elapsed, reference_std, chain, timed_joints,
           common_covariance, reference_turn_std, fitted_dof):
        """Return the key of :meth:`Integrity._assessed`'s arguments."""
        def exact(values):
            return None if values is None else np.asarray(values, dtype=float)
        return cls(measurements, exact(joints), exact(reference), elapsed,
                   exact(reference_std), bool(chain), exact(timed_joints),
                   exact(common_covariance), exact(reference_turn_std), fitted_dof)

    def __eq__(self, other):
        if not isinstance(other, _AssessmentKey):
            return NotImplemented
        return self.measurements is other.measurements and self.parts == other.parts

    __hash__ = None


def _mirror_planes(model):
    """
    Return the planes :meth:`Integrity.mirrors` reflects across: a point and a normal each.

    The vertical plane through the slew axis that best fits the anchors, and the plane
    that best fits them in space: ``(centre, across, mean, normal)``, (3,) each, metres and
    unit vectors. They depend on the anchors alone: computed with the checks, not per frame.
    """
    anchors = model.anchors
    horizontal = anchors[:, :2] - model.base[:2]
    direction = np.linalg.svd(horizontal, full_matrices=False)[2][0]
    across = np.r_[-direction[1], direction[0], 0.0]
    centre = np.r_[model.base[:2], 0.0]
    centred = anchors - anchors.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    return centre, across, anchors.mean(axis=0), normal


def _verdict(checks, values):
    """Return the :class:`Verdict` of (level, status, message) checks, naming the worst."""
    if not checks:
        return Verdict(OK, 'ok', 'tracking', values)
    level = max(level for level, _, _ in checks)
    worst = [check for check in checks if check[0] == level]
    return Verdict(level, worst[0][1], '; '.join(message for _, _, message in worst), values)
