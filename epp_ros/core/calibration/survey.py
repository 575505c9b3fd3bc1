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
Anchor self-survey: the free anchors located from anchor-anchor ranges, before the boom moves.

Anchors that range each other (TREK1000 ``ma`` lines, DWM1001 anchors) measure
``||a_i - a_j|| + o_i + o_j`` (``o``: each anchor's range offset, its antenna delay).
:func:`survey_anchors` fits the free anchors' positions, and the anchor offsets, to rounds
of these ranges by robust least squares (the NLOS mixture of ``core.nlos``, as
``core.calibrate``), starting from the configured positions.

What the ranges cannot tell, the configuration does: the fit carries a Gaussian prior on
each free anchor's coordinates (``prior_sigma`` about its configured position) and on each
anchor offset (``offset_sigma`` about its configured value). The standard deviations are
the posterior's, so a parameter the ranges do not determine is reported as known to about
its prior, and named:

- a rotation of the free anchors about the fixed ones changes no anchor-anchor range: about
  the fixed anchor (one fixed), about the line through them (two), none (three or more not
  on a line); a mirror image is resolved by starting at the configured positions;
- anchors that are nearly coplanar (outriggers on the ground, nothing high) barely see each
  other's heights: the ranges change only to second order with them;
- the offsets: pair sums ``o_i + o_j`` determine every ``o_i`` when the positions are known
  and the pairs' graph has an odd cycle (any three anchors ranging each other), but with
  free positions the ``m (m - 1) / 2`` pairs may be too few for positions and offsets
  together (six anchors, four free: 15 pairs, 17 unknowns beyond the rotation); a
  recording of the moving boom (``calibrate(..., anchor_ranges=...)``) then pins them.

The prior also pulls, by the ratio of its information to the ranges', on what the ranges
do determine: negligible once ``sigma / sqrt(K)`` is well below ``prior_sigma``. The fit is
Levenberg-Marquardt, by plain least squares first (far from the solution the NLOS loss
would call every range blocked), then under the mixture; along the rotation no range sees,
each step is followed by the rotation (Kabsch) that brings the free anchors nearest their
configured places, which is where the prior puts them along it.
"""
from dataclasses import dataclass, field
import operator

from epp_ros.core.model.nlos import NlosMixture
from epp_ros.core.model.noise import DEFAULT_NOISE
from epp_ros.core.solvers.levenberg_marquardt import levenberg_marquardt, marquardt_step
import numpy as np

__all__ = ['SurveyResult', 'survey_anchors', 'AnchorPairs', 'ANCHOR_TOLERANCE',
           'OFFSET_TOLERANCE']

#: Metres: anchors less certain than this (std along their worst direction) are reported
#: as poorly determined; the calibration issue's target accuracy.
ANCHOR_TOLERANCE = 0.05

#: Metres: offsets less certain than this are reported as poorly determined.
OFFSET_TOLERANCE = 0.03

#: A parameter whose posterior std is above this fraction of its prior's is resolved by the
#: configuration rather than by the ranges.
PRIOR_DOMINATED = 0.5


@dataclass
class SurveyResult:
    """
    What :func:`survey_anchors` found, how well it is determined, and the verdict.

    Standard deviations are the posterior's (the ranges' information, scaled by the
    residual variance, plus the configuration's prior); zero for fixed anchors.
    """

    status: str                 #: ``"ok"``, ``"poorly_determined"`` or ``"not_converged"``
    message: str                #: the verdict: what is poorly determined and why
    anchors: np.ndarray         #: (m, 3) metres
    anchor_std: np.ndarray      #: (m, 3) metres per axis
    anchor_offsets: np.ndarray  #: (m,) metres: fitted, or the configured ones if not
    anchor_offset_std: np.ndarray = None    #: (m,) metres; None when not estimated
    residual_rms: float = float('nan')      #: metres, RMS of measured less fitted ranges
    residual_scale: float = float('nan')    #: residual standard deviation over ``sigma``
    poorly_determined: list = field(default_factory=list)  #: names of uncertain parameters
    free: tuple = ()            #: the anchors fitted
    rounds: int = 0             #: K
    pairs: int = 0              #: anchor pairs with at least one range
    converged: bool = False
    iterations: int = 0
    covariance: np.ndarray = None   #: of (free anchors' xyz, offsets if estimated)
    nlos: np.ndarray = None     #: (K, m, m) posterior NLOS probability of each range

    @property
    def success(self):
        """Return whether the survey converged and determined everything."""
        return self.status == 'ok'

    @property
    def offsets_estimated(self):
        """Return whether the anchor offsets were fitted."""
        return self.anchor_offset_std is not None


def fixed_indices(fixed_anchors, m):
    """Return sorted distinct anchor indices in 0..m-1, or raise a ValueError naming them."""
    try:
        fixed = tuple(operator.index(j) for j in fixed_anchors)
    except TypeError:
        raise ValueError(f'fixed_anchors must be anchor indices, got {fixed_anchors!r}') \
            from None
    if any(not 0 <= j < m for j in fixed) or len(set(fixed)) != len(fixed):
        raise ValueError(f'fixed_anchors must be distinct indices in 0-{m - 1}, got '
                         f'{list(fixed)}')
    return tuple(sorted(fixed))


def anchor_range_rounds(values, m, name='anchor_ranges'):
    """
    Return ``values`` as rounds (K, m, m) of floats: non-finite, negative, diagonal -> NaN.

    One (m, m) round is taken as K = 1. Raises one ValueError naming what is expected.
    """
    expected = (f'{name} must be rounds of anchor-anchor ranges in metres, an array of '
                f'shape (K, {m}, {m}) with K >= 1 (NaN where missing)')
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'{expected}; got {type(values).__name__}') from None
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or array.shape[1:] != (m, m) or len(array) == 0:
        raise ValueError(f'{expected}; got shape {array.shape}')
    with np.errstate(invalid='ignore'):
        array[~np.isfinite(array) | (array < 0)] = np.nan
    array[:, np.arange(m), np.arange(m)] = np.nan
    return array


def irls(loss, scaled, mask):
    """
    Return the robust cost, its slope, the IRLS weights and the NLOS probabilities.

    ``scaled``: ``(predicted - measured) / sigma`` (any shape), ``loss``: an
    ``NlosMixture`` bound to the ranges' sigmas, called on the excess ``-scaled``; all four
    are zero where ``mask`` is False.
    """
    cost, excess_slope, nlos = loss(-scaled)
    slope = np.where(mask, -excess_slope, 0.0)
    weights = np.ones_like(scaled)
    large = np.abs(scaled) > 1.0
    weights[large] = np.clip(slope[large] / scaled[large], 1e-3, 1.0)
    return (np.where(mask, cost, 0.0), slope, np.where(mask, weights, 0.0),
            np.where(mask, nlos, 0.0))


class AnchorPairs:
    """
    Rounds of anchor-anchor ranges as robust least-squares terms.

    Parameters
    ----------
    rounds : ndarray, shape (K, m, m)
        Metres, NaN where missing (:func:`anchor_range_rounds`).
    sigma : float
        Metres.
    mixture : NlosMixture

    """

    def __init__(self, rounds, sigma, mixture):
        m = rounds.shape[1]
        self.first, self.second = np.nonzero(~np.eye(m, dtype=bool))
        self.measured = rounds[:, self.first, self.second]            # (K, P)
        self.mask = np.isfinite(self.measured)
        self.sigma = float(sigma)
        self.bind(mixture)

    def bind(self, mixture):
        """Fit the ranges under ``mixture`` (an ``NlosMixture``) from now on."""
        self.loss = mixture.bind(np.full(self.measured.shape, self.sigma))

    def residuals(self, anchors, offsets, anchor_column, offset_column, n_x):
        """
        Return the scaled residuals, shape (K, P), 0 where missing, and their Jacobian.

        The Jacobian has shape (P, n_x), in units of 1 / sigma.

        ``anchor_column`` (m,): the column of each anchor's x coordinate (y, z next), -1 if
        fixed; ``offset_column`` (m,): the column of each anchor's offset, -1 if not fitted.
        """
        vectors = anchors[self.first] - anchors[self.second]
        distances = np.linalg.norm(vectors, axis=1)
        predicted = distances + offsets[self.first] + offsets[self.second]
        scaled = np.where(self.mask, (predicted - np.nan_to_num(self.measured)) / self.sigma,
                          0.0)
        units = vectors / np.maximum(distances, 1e-12)[:, None]
        jacobian = np.zeros((distances.size, n_x))
        rows = np.arange(distances.size)
        for ends, sign in ((self.first, 1.0), (self.second, -1.0)):
            moving = anchor_column[ends] >= 0
            for axis in range(3):
                jacobian[rows[moving], anchor_column[ends][moving] + axis] = \
                    sign * units[moving, axis]
            fitted = offset_column[ends] >= 0
            jacobian[rows[fitted], offset_column[ends][fitted]] += 1.0
        return scaled, jacobian / self.sigma

    def terms(self, anchors, offsets, anchor_column, offset_column, basis):
        """
        Return the robust cost, its gradient, the Gauss-Newton information and the parts.

        ``basis`` (n_x, n_q) maps the parameters' changes (see :meth:`residuals`); the
        gradient (n_q,) and information (n_q, n_q) are in its coordinates, the parts are
        the scaled residuals, IRLS weights and NLOS probabilities, each (K, P).
        """
        scaled, jacobian = self.residuals(anchors, offsets, anchor_column, offset_column,
                                          basis.shape[0])
        jacobian = jacobian @ basis
        cost, slope, weights, nlos = irls(self.loss, scaled, self.mask)
        information = jacobian.T @ (weights.sum(axis=0)[:, None] * jacobian)
        return (float(cost.sum()), jacobian.T @ slope.sum(axis=0), information,
                (scaled, weights, nlos))


class _Survey:
    """The survey's least squares: parameters, the pairs' terms and the prior."""

    def __init__(self, model, rounds, fixed, sigma, prior_sigma, offsets, offset_sigma):
        m = model.n_anchors
        self.model, self.m, self.sigma = model, m, sigma
        self.free = np.array([j for j in range(m) if j not in fixed], dtype=int)
        self.fixed, self.offsets = fixed, offsets
        self.pairs = AnchorPairs(rounds, sigma, NlosMixture(0.0))
        self.mask = self.pairs.mask
        n_anchor = 3 * self.free.size
        self.n_x = n_anchor + (m if offsets else 0)
        self.x0 = np.r_[model.anchors[self.free].ravel(),
                        model.anchor_offsets if offsets else np.zeros(0)]
        self.prior = np.r_[np.full(n_anchor, float(prior_sigma)),
                           np.full(self.n_x - n_anchor, float(offset_sigma))]
        self.anchor_column = np.full(m, -1)
        self.anchor_column[self.free] = 3 * np.arange(self.free.size)
        self.offset_column = n_anchor + np.arange(m) if offsets else np.full(m, -1)

    def unpack(self, x):
        """Return anchors (m, 3) and anchor offsets (m,) of ``x``."""
        anchors = self.model.anchors.copy()
        anchors[self.free] = x[:3 * self.free.size].reshape(-1, 3)
        offsets = x[3 * self.free.size:] if self.offsets else self.model.anchor_offsets
        return anchors, offsets

    def align(self, x):
        """
        Return ``x`` with the free anchors moved rigidly nearest their configured places.

        The motion is the one no anchor-anchor range sees (:func:`_gauge_kind`), so this
        minimises the prior along it exactly; None when the fixed anchors leave none.
        """
        kind = _gauge_kind(self.model, self.fixed)
        if kind is None or self.free.size == 0:
            return None
        n_anchor = 3 * self.free.size
        anchors, target = x[:n_anchor].reshape(-1, 3), self.model.anchors[self.free]
        fixed = self.model.anchors[list(self.fixed)]
        if kind == 'rigid':
            centre, goal = anchors.mean(axis=0), target.mean(axis=0)
        else:
            centre = goal = fixed.mean(axis=0)
        axis = np.linalg.svd(fixed - centre)[2][0] if kind == 'axis' else None
        turned = x.copy()
        turned[:n_anchor] = (goal + (anchors - centre) @ _turn(anchors - centre, target - goal,
                                                               axis).T).ravel()
        return turned

    def state(self, x):
        """Return the cost, gradient, the ranges' information and the IRLS parts at ``x``."""
        anchors, offsets = self.unpack(x)
        cost, gradient, information, parts = self.pairs.terms(
            anchors, offsets, self.anchor_column, self.offset_column, np.eye(self.n_x))
        prior = (x - self.x0) / self.prior
        return cost + 0.5 * float(prior @ prior), gradient + prior / self.prior, \
            information, parts


def _fit(problem, x, max_iter, tol):
    """Levenberg-Marquardt on the robust cost plus the prior from ``x``; x, parts, iterations."""
    prior_information = np.diag(problem.prior ** -2.0)

    def evaluate(x):
        cost, gradient, information, parts = problem.state(x)
        return cost, (gradient, information, parts)

    def turn(x, cost, state):
        # The gauge's curved valley, in one move.
        turned = problem.align(x)
        if turned is not None:
            trial = evaluate(turned)
            if trial[0] <= cost:
                return (turned,) + trial
        return x, cost, state

    # No ridge and no damping floor near 1e-9: what only the prior resolves has a curvature
    # many orders below the ranges', and a damping scaled by the diagonal would freeze it.
    fit = levenberg_marquardt(
        x, evaluate, lambda x, state: (state[1] + prior_information, state[0]),
        max_iter=max_iter, tol=tol, step=marquardt_step(ridge=0.0), stall=1e-12,
        damping_floor=1e-15, refine=turn)
    _, information, parts = fit.state
    return fit.x, information, parts, fit.iterations, fit.converged


def _posterior(problem, information, parts):
    """
    Return the posterior covariance (n_x, n_x), the residual scale and its data RMS.

    In the prior's units the ranges' information is eigendecomposed, what it does not see
    (relative eigenvalues below 1e-10) cleared, and each direction's variance inverted on
    its own: stable however precise the ranges.
    """
    scaled, weights, _ = parts
    prior = problem.prior
    values, vectors = np.linalg.eigh(prior[:, None] * information * prior[None, :])
    seen = values > 1e-10 * max(values[-1], 1e-300)
    dof = float(weights.sum()) - seen.sum()
    scale = float(np.sqrt(np.sum(weights * scaled ** 2) / dof)) if dof > 0 else 1.0
    shrink = 1.0 / (1.0 + np.where(seen, values, 0.0) / max(scale, 1e-6) ** 2)
    covariance = prior[:, None] * ((vectors * shrink) @ vectors.T) * prior[None, :]
    rms = float(np.sqrt(np.mean(scaled[problem.mask] ** 2))) * problem.sigma
    return 0.5 * (covariance + covariance.T), scale, rms


def _planarity(anchors):
    """Return the anchors' RMS distance from their best plane, metres."""
    centred = anchors - anchors.mean(axis=0)
    return float(np.linalg.svd(centred, compute_uv=False)[-1] / np.sqrt(len(anchors)))


def _gauge_kind(model, fixed):
    """
    Return the rigid motion of the free anchors no anchor-anchor range sees.

    ``'rigid'`` (no anchor fixed), ``'point'`` (a rotation about the one fixed anchor),
    ``'axis'`` (about the line through the fixed anchors, within 0.1 m) or None.
    """
    if len(fixed) == 0:
        return 'rigid'
    if len(fixed) == 1:
        return 'point'
    centred = model.anchors[list(fixed)] - model.anchors[list(fixed)].mean(axis=0)
    return 'axis' if np.linalg.svd(centred, compute_uv=False)[1] < 0.1 else None


def _rotation_story(model, fixed):
    """Return which rotation of the free anchors the fixed ones leave free, or ''."""
    kind = _gauge_kind(model, fixed)
    if kind == 'rigid':
        return 'nothing fixes the frame: every rigid motion of the anchors'
    if kind == 'point':
        return f'a rotation of the free anchors about fixed anchor {fixed[0]}'
    if kind == 'axis':
        names = ', '.join(map(str, fixed))
        return f'a rotation of the free anchors about the line through fixed anchors {names}'
    return ''


def _turn(moved, target, axis=None):
    """
    Return the rotation (3, 3) taking the points ``moved`` (n, 3) nearest to ``target``.

    Least squares (Kabsch), proper; about ``axis`` (3,) alone when given.
    """
    if axis is not None:
        angle = np.arctan2(np.sum(np.cross(moved, target) @ axis),
                           np.sum(moved * target) - np.sum((moved @ axis) * (target @ axis)))
        cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                          [-axis[1], axis[0], 0.0]])
        return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross
    left, _, right = np.linalg.svd(moved.T @ target)
    sign = np.sign(np.linalg.det(right.T @ left.T)) or 1.0
    return right.T @ np.diag([1.0, 1.0, sign]) @ left.T


def _anchor_findings(problem, covariance, fixed, tolerance):
    """Return the names and advice of the poorly located free anchors."""
    names, advice = [], []
    rotation = _rotation_story(problem.model, fixed)
    planar = _planarity(problem.model.anchors)
    for index, j in enumerate(problem.free):
        values, vectors = np.linalg.eigh(covariance[3 * index:3 * index + 3,
                                                    3 * index:3 * index + 3])
        worst = float(np.sqrt(max(values[-1], 0.0)))
        if worst <= tolerance:
            continue
        direction = vectors[:, -1] * np.sign(vectors[np.argmax(np.abs(vectors[:, -1])), -1])
        if abs(direction[2]) > 0.7 and planar < 1.0:
            why = (f'its height: the anchors are nearly coplanar ({planar:.2g} m RMS off '
                   'their plane), and their ranges barely see heights')
        elif rotation:
            why = f'{rotation} changes no anchor-anchor range'
        else:
            why = 'the ranges confound it with the other parameters (too few pairs)'
        prior = (', resolved only by its configured position'
                 if worst > PRIOR_DOMINATED * problem.prior[0] else '')
        names.append(f'anchor {j}')
        advice.append(f'anchor {j} is located to +-{worst:.3g} m along ({direction[0]:.2f}, '
                      f'{direction[1]:.2f}, {direction[2]:.2f}): {why}{prior}')
    return names, advice


def _offset_findings(problem, covariance, pairs, tolerance):
    """Return the names and advice when the anchor offsets are poorly determined."""
    if not problem.offsets:
        return [], []
    std = np.sqrt(np.maximum(np.diag(covariance)[3 * problem.free.size:], 0.0))
    poor = np.flatnonzero(std > tolerance)
    if poor.size == 0:
        return [], []
    unknowns = 3 * problem.free.size + problem.m
    return ([f'offset of anchor {j}' for j in poor],
            [f'the offsets of anchors {", ".join(map(str, poor))} are known to '
             f'+-{std[poor].min():.3g} to {std[poor].max():.3g} m: {pairs} anchor pairs for '
             f'{unknowns} positions and offsets confound them with the positions of the '
             'free anchors; a recording of the moving boom (calibrate with anchor_ranges) pins '
             'them'])


def _measured_pairs(rounds, free):
    """Return the count of anchor pairs ranged; raise if a free anchor has none."""
    heard = np.isfinite(rounds).any(axis=0)
    heard = heard | heard.T
    if not heard.any():
        raise ValueError('anchor_ranges has no finite range between two anchors: nothing '
                         'to survey')
    deaf = [int(j) for j in free if not heard[j].any()]
    if deaf:
        raise ValueError(f'anchor_ranges has no range to or from anchor(s) {deaf}: they '
                         'cannot be surveyed (fix them, or record their ranges)')
    return int(np.triu(heard, 1).sum())


def survey_anchors(model, anchor_ranges, *, fixed_anchors=(0,), sigma=DEFAULT_NOISE.sigma,
                   prior_sigma=0.5, offsets=True, offset_sigma=0.5,
                   nlos_fraction=DEFAULT_NOISE.nlos_fraction,
                   nlos_gamma=DEFAULT_NOISE.nlos_gamma,
                   max_iter=100, tol=1e-10, anchor_tolerance=ANCHOR_TOLERANCE,
                   offset_tolerance=OFFSET_TOLERANCE):
    """
    Locate the free anchors (and fit the anchor offsets) from anchor-anchor ranges alone.

    Parameters
    ----------
    model : BoomModel
        The boom as configured: the fixed anchors' positions define the truck frame; the
        free anchors' positions and the anchor offsets are the start and the prior.
    anchor_ranges : array_like, shape (K, m, m) or (m, m)
        K >= 1 rounds of ranges, metres: ``[k, i, j]`` anchor i's range to anchor j in
        round k, ``||a_i - a_j|| + o_i + o_j`` plus noise; NaN (or any non-finite or
        negative value) where missing; the diagonal is ignored.
    fixed_anchors : sequence of int
        Anchors on the truck body whose configured positions are kept.
    sigma : float
        Anchor-anchor range standard deviation, metres.
    prior_sigma : float
        Metres per axis: how far a free anchor may be from its configured position; what
        resolves a rotation about the fixed anchors and a poorly seen height.
    offsets : bool
        Fit the anchor offsets too (else keep the configured ones).
    offset_sigma : float
        Metres: how far an anchor offset may be from its configured value.
    nlos_fraction, nlos_gamma : float
        The NLOS mixture (prior blocked fraction, mean excess in metres) the ranges are
        fitted under; ``nlos_fraction=0``: plain least squares.
    max_iter : int
        Levenberg-Marquardt iterations.
    tol : float
        Metres: stop when no parameter moves more than this.
    anchor_tolerance, offset_tolerance : float
        Metres: anchors (std along their worst direction) and offsets (std) less certain
        than these are reported as poorly determined.

    Returns
    -------
    SurveyResult

    Raises
    ------
    ValueError
        On a wrong shape, no range at all, a free anchor without ranges, bad fixed anchors
        or a non-positive sigma.

    """
    m = model.n_anchors
    rounds = anchor_range_rounds(anchor_ranges, m)
    fixed = fixed_indices(fixed_anchors, m)
    for name, value in (('sigma', sigma), ('prior_sigma', prior_sigma),
                        ('offset_sigma', offset_sigma)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f'{name} must be a positive number of metres, got {value!r}')
    mixture = NlosMixture(float(nlos_fraction), float(nlos_gamma))
    problem = _Survey(model, rounds, fixed, float(sigma), prior_sigma, bool(offsets),
                      offset_sigma)
    pairs = _measured_pairs(rounds, problem.free)
    # Least squares first: far from the solution the NLOS loss would take every range
    # for blocked and hardly move.
    problem.pairs.bind(NlosMixture(0.0))
    x, _, _, first, _ = _fit(problem, problem.x0, max_iter, tol)
    problem.pairs.bind(mixture)
    x, information, parts, iterations, converged = _fit(problem, x, max_iter, tol)
    iterations += first
    covariance, scale, rms = _posterior(problem, information, parts)
    anchors, anchor_offsets = problem.unpack(x)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    anchor_std = np.zeros((m, 3))
    anchor_std[problem.free] = std[:3 * problem.free.size].reshape(-1, 3)
    names, advice = _anchor_findings(problem, covariance, fixed, anchor_tolerance)
    more = _offset_findings(problem, covariance, pairs, offset_tolerance)
    names, advice = names + more[0], advice + more[1]
    if not converged:
        status = 'not_converged'
        message = f'the survey did not converge in {max_iter} iterations'
    elif names:
        status = 'poorly_determined'
        message = 'the anchor-anchor ranges do not determine everything: ' + '; '.join(advice)
    else:
        status = 'ok'
        message = (f'surveyed {problem.free.size} free anchors from {len(rounds)} rounds of '
                   f'{pairs} pairs: range RMS {rms:.3g} m')
    nlos = np.zeros(rounds.shape)
    nlos[:, problem.pairs.first, problem.pairs.second] = parts[2]
    return SurveyResult(
        status=status, message=message, anchors=anchors, anchor_std=anchor_std,
        anchor_offsets=np.array(anchor_offsets, dtype=float),
        anchor_offset_std=std[3 * problem.free.size:] if problem.offsets else None,
        residual_rms=rms, residual_scale=scale, poorly_determined=names,
        free=tuple(int(j) for j in problem.free), rounds=len(rounds), pairs=pairs,
        converged=converged, iterations=iterations, covariance=covariance, nlos=nlos)
