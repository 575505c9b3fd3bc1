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
Chain estimator: least squares over the boom's p + 1 angles (slew and one pitch each).

A pump boom has exactly p + 1 degrees of freedom, so both of the paper's features (fixed
lengths, one vertical plane) hold by construction. Levenberg–Marquardt with the analytic
Jacobian fits the ranges, warm-started from the previous frame; it is the maximum-likelihood
estimate under Gaussian range noise and attains the Cramér–Rao bound (``core.bounds``).

NLOS ranges are always too long. Ranges are fitted under a Gaussian plus exponential-excess
mixture (``core.nlos``): the maximum-likelihood estimate when some links are blocked, where
a blocked link pulls the fit with a bounded force and is reported per frame as NLOS when it
is more likely blocked than not.

Tag-tag ranges, inclinometers and a slew encoder, when given, enter the same least squares
with their own sigmas (``core.measurements``), so the paper's TPSM angles add information
instead of being discarded.

Joints stay above ``lowest_joint`` through a stiff penalty (the boom is above the ground).
Without a previous pose the global solution is searched for: a beam search grows chains
section by section over a grid of slews, every candidate gets a few iterations, the best are
fitted to the end, and from the best fit each joint is folded the other way and the tip
tried at its other well-fitting pitches until nothing fits better.
"""
from dataclasses import replace
from functools import lru_cache
from typing import NamedTuple

from epp_ros.core.model.folds import folded_angles, tip_circle, tip_minima
from epp_ros.core.model.measurements import Residuals, SensorNoise, wrap_angle
from epp_ros.core.model.nlos import NlosMixture, OUTLIER_FRACTION, range_excess
from epp_ros.core.model.noise import DEFAULT_NOISE, fitted_link_bias
from epp_ros.core.model.plane import fit_slew, to_plane
from epp_ros.core.solvers.compiled import kernel
from epp_ros.core.solvers.levenberg_marquardt import levenberg_marquardt, \
    levenberg_marquardt_batch, LevenbergMarquardtResult, STALL
import numpy as np
from scipy.special import bdtrc

__all__ = ['ChainMethod', 'Fit', 'SearchExhausted', 'angles_from_joints', 'canonical_angles',
           'grow_chains']

#: A screening fit leaning on more of its ranges (blocked or outliers by the judge) than
#: the judge's shares give this chance has a sigma told too small (``_screened``).
LEANING_TAIL = 1e-3


#: The chain's and the tracker's compiled fit (``core.solvers.compiled``).
KERNEL = 'epp_ros.core.estimation.methods.compiled_chain'


def angles_from_joints(model, joints):
    """Slew and pitches (radians) of the chain closest to the given joints (p, 3)."""
    joints = np.ascontiguousarray(joints, dtype=float)
    slew, pitches = _angles(model, joints.tobytes(), joints.shape)
    return slew, pitches.copy()


@lru_cache(maxsize=8)
def _angles(model, joints_bytes, shape):
    """
    Return :func:`angles_from_joints` of the joints ``joints_bytes`` of ``shape``, kept.

    A frame's judgement, its separation fits, its publication and the next frame's warm
    start all ask for the same posture's (a model's arrays are read-only). The last eight
    are kept, and with them up to eight models.
    """
    joints = np.frombuffer(joints_bytes, dtype=float).reshape(shape)
    slew = fit_slew(joints, model.base)
    if model.pivot_offset == 0.0:
        return float(wrap_angle(slew)), _pitches_in_plane(model, joints, slew)
    fits = []
    for candidate in (slew, slew + np.pi):      # a pivot off the axis: on which side is it?
        pitches = _pitches_in_plane(model, joints, candidate)
        error = np.sum((model.forward_kinematics(candidate, pitches) - joints) ** 2)
        fits.append((error, float(wrap_angle(candidate)), pitches))
    _, slew, pitches = min(fits, key=lambda fit: fit[0])
    return slew, pitches


def _pitches_in_plane(model, joints, slew):
    """Return the pitches (p,) of the sections to the joints (p, 3), in the plane of ``slew``."""
    coords = to_plane(np.vstack([model.pivot(slew), joints]), model.base, slew)
    steps = np.diff(coords, axis=0)
    return np.arctan2(steps[:, 1], steps[:, 0])


def canonical_angles(psi, pivot_offset=0.0):
    """
    Return the same chain with its first section pointing outward, angles in [-pi, pi).

    With the pivot on the slew axis, ``(slew, pitch)`` and ``(slew + pi, pi - pitch)``
    describe the same boom; the slew is the direction the first section points. A pivot
    off the axis tells them apart, and only the wrapping applies.
    """
    psi = np.array(psi, dtype=float)
    if pivot_offset == 0.0 and np.cos(psi[1]) < 0:
        psi = np.r_[psi[0] + np.pi, np.pi - psi[1:]]
    return wrap_angle(psi)


def grow_chains(model, measurements, range_sigma, mixture, slews, lowest_joint, width=8,
                candidates=72):
    """
    Chains grown section by section for each slew, keeping the ``width`` best so far.

    Each section's pitch is taken from a grid (or its inclinometer), scored by the NLOS
    loss of its tag's ranges, with joints below ``lowest_joint`` excluded. Keeping several
    partial chains, not the single best, recovers folds that only later tags reveal and
    tags whose best-looking pitch is pulled by a blocked link. The chain's cold start and
    CEPP's (``core.epp``) both start from them.

    Parameters
    ----------
    model : BoomModel
        The boom and its anchors.
    measurements : Measurements
        The frame.
    range_sigma : ndarray, shape (p, m)
        Each tag-anchor range's standard deviation, metres.
    mixture : NlosMixture
        The range error model that scores a tag's ranges.
    slews : ndarray, shape (s,)
        Slews to grow chains at, radians.
    lowest_joint : float
        No joint below this height, metres.
    width : int
        Partial chains kept per slew.
    candidates : int
        Pitches of the grid over [-pi, pi) tried for a section without an inclinometer.

    Returns
    -------
    pitches : ndarray, shape (s, width, p)
        Candidate pitches per slew, best first.
    cost : ndarray, shape (s, width)
        Their loss over the ranges (inf for chains that could not stay above ground).

    """
    grid = np.linspace(-np.pi, np.pi, candidates, endpoint=False)
    along = np.stack([np.cos(slews), np.sin(slews), np.zeros_like(slews)], axis=-1)
    up = np.array([0.0, 0.0, 1.0])
    joints = np.broadcast_to(model.pivot(slews)[:, None, :], (slews.size, 1, 3))
    pitches = np.zeros((slews.size, 1, 0))
    cost = np.zeros((slews.size, 1))
    for k, length in enumerate(model.arm_lengths):
        options = grid if np.isnan(measurements.pitches[k]) else measurements.pitches[k:k + 1]
        step = length * (np.cos(options)[None, :, None] * along[:, None, :]
                         + np.sin(options)[:, None] * up)                 # (s, c, 3)
        ends = joints[:, :, None, :] + step[:, None, :, :]                # (s, w, c, 3)
        added = np.where(ends[..., 2] < lowest_joint, np.inf, 0.0)
        if np.isfinite(measurements.ranges[k]).any():
            added = added + _tag_loss(model, mixture, k, ends, measurements, range_sigma)
        elif options.size > 1:
            added = added + np.abs(options)     # unseen section: prefer level
        total = (cost[:, :, None] + added).reshape(slews.size, -1)
        keep = np.argsort(total, axis=1)[:, :width]                       # (s, w)
        rows = np.arange(slews.size)[:, None]
        parent, choice = np.divmod(keep, options.size)
        joints = ends.reshape(slews.size, -1, 3)[rows, keep]
        pitches = np.concatenate([pitches[rows, parent],
                                  np.broadcast_to(options, (slews.size, options.size))[
                                      rows, choice][..., None]], axis=-1)
        cost = total[rows, keep]
    return pitches, cost


def _tag_loss(model, mixture, k, ends, measurements, range_sigma):
    """Approximate NLOS loss of tag ``k``'s measured ranges at candidate joints (..., 3)."""
    excess = range_excess(ends, model.anchors, measurements.ranges[k], range_sigma[k])
    return mixture.approximate_loss(excess, range_sigma[k]).sum(axis=-1)


def judged_minimum(minimise, losses, scaled_of, judged_cost, start, also=(), refit=True):
    """
    Minimise a frame's loss as the judge weighs it (``NlosMixture.judged``: with outliers).

    First under the fit's NLOS mixture alone, whose pull never fades: a start metres off
    still finds its way, where the judge's loss would stop with the ranges not reached
    yet taken for outliers. Then under the judge's: where a range looks like an outlier at
    that fit, from the fit and from ``start`` and each of ``also`` (the outliers may have
    pulled the first fit off: a site where a fifth of the ranges are outliers puts one
    tag's two on a wrong fold); else from those starts the judge likes better than the
    first fit (that fit ran from a range no noise explains).

    Parameters
    ----------
    minimise : callable
        ``minimise(x, judged) -> LevenbergMarquardtResult`` from ``x``, under the
        judge's loss or the fit's.
    losses : (LinkLoss, LinkLoss)
        The frame's ranges' bound losses, the fit's and the judge's (the same object when
        they are one).
    scaled_of : callable
        ``scaled_of(result)``: the ranges' scaled residuals (n,) where ``result`` stopped.
    judged_cost : callable
        ``judged_cost(x)``: the judge's cost at ``x``.
    start : ndarray
        Where the first fit starts.
    also : sequence of ndarray
        More starts.
    refit : bool
        False: a screening fit, :func:`_screened`: the first fit at the judge's cost,
        or the judge's own descent from ``start`` where the first leans on a range the
        judge may read otherwise.

    Returns
    -------
    LevenbergMarquardtResult
        The one with the lowest judge's cost, that cost its ``cost``; ``iterations`` of
        all the fits together.

    """
    fitting, judging = losses
    first = minimise(start, False)
    if judging is fitting:
        return first
    scaled = scaled_of(first)
    first = replace(first, cost=first.cost
                    + float(np.sum(judging(-scaled)[0] - fitting(-scaled)[0])))
    if not refit:
        return _screened(minimise, judging, scaled, judged_cost, start, first)
    # Ranges that look like outliers at the first fit may have pulled it off: the judge's
    # descent starts there and from every start given.
    if np.any(judging.posteriors(-scaled)[1] > 0.5):
        starts = [first.x, start, *also]
    else:
        starts = [x for x in (start, *also) if judged_cost(x) < first.cost]
    results = [first] + [minimise(x, True) for x in starts]
    best = min(results, key=lambda result: result.cost)
    return replace(best, iterations=sum(result.iterations for result in results))


def _screened(minimise, judging, scaled, judged_cost, start, first):
    """
    Return :func:`judged_minimum`'s screening fit: ``first``, or better where the judge says.

    Where the first fit leans on a few ranges the mixture calls blocked or outliers, the
    judge's descent runs from ``start`` too: a fold tried next to a range metres short
    is pulled back by it under the NLOS mixture alone (whose short side is Gaussian) and
    explains three other ranges as blocked instead, a fit the judge finds 14 nats less
    likely than the fold's own. Not where more look so than the judge's shares of blocked
    links and outliers make likely (a binomial tail under ``LEANING_TAIL``): that is a
    sigma told too small (the estimator then rescales it), and at that sigma the judge
    would let go of ranges that are only noisy. Else ``start`` itself, where the judge
    likes it better.
    """
    blocked, outlying = judging.posteriors(-scaled)
    leaning = np.count_nonzero(np.maximum(blocked, outlying) > 0.5)
    if leaning and bdtrc(leaning - 1, scaled.size, judging.off_line) >= LEANING_TAIL:
        second = minimise(start, True)
        best = second if second.cost < first.cost else first
        return replace(best, iterations=first.iterations + second.iterations)
    start_cost = judged_cost(start)
    return replace(first, x=start, cost=start_cost) if start_cost < first.cost else first


class Fit(NamedTuple):
    """A Levenberg–Marquardt fit: where it stopped and whether it had converged there."""

    psi: np.ndarray             #: (p + 1,) slew and pitches, radians
    cost: float                 #: the loss there
    iterations: int
    converged: bool             #: stopped by its tolerances, not by ``max_iter``


class SearchExhausted(RuntimeError):
    """A global search that reached its iteration budget: the frame is not solved."""


class ChainMethod:
    """
    Levenberg–Marquardt over (slew, pitch_1..pitch_p) on everything measured.

    Parameters
    ----------
    model : BoomModel
    sigma : float
        Tag-anchor range standard deviation, metres: weighs the ranges against the other
        sensors, scales the NLOS threshold and the predicted uncertainty.
    eta : float
        Multiplicative range noise factor (the paper's): a range r has standard deviation
        ``sqrt(sigma^2 + (eta r)^2)``.
    tag_sigma : float or None
        Tag-tag range standard deviation, metres (None: ``sigma``).
    pitch_sigma, slew_sigma : float
        Inclinometer and slew encoder standard deviations, radians.
    nlos_fraction : float
        Prior probability that a range is NLOS; 0 for plain least squares.
    nlos_gamma : float
        Mean NLOS excess, metres.
    tol : float
        Stop when the step is below ``tol`` radians.
    max_iter : int
    slew_starts : int
        Slews tried by the cold start.
    screen_iterations : int
        Iterations given to every cold start before only the best are fitted to the end.
    search_budget : int
        Iterations one global search may take (a cold start takes about 200, 300 at
        most; a frame of garbage up to 600). A search that reaches it raises
        :class:`SearchExhausted`, and the next frame's search continues where it stopped,
        so that the time per frame stays bounded whatever arrives.
    lowest_joint : float
        No joint is below this height, metres (world z = 0 is the ground; the default
        leaves room for noise). Lower it for a boom that reaches below grade.
    link_bias_std : float or array_like, shape (p, m)
        What is unknown of each link's own bias, metres: per link, the fit weighs each
        range by it (``core.model.noise.fitted_link_bias``); one number changes no weight.

    """

    prior = 'optional'          # one more start; the cold start finds the global solution
    holds_chain = True
    #: How far, metres, a joint may sink below ``lowest_joint`` per unit of cost.
    GROUND_SIGMA = 0.05
    #: Sigmas of the ranges in a cold search's screening fits, times theirs (:meth:`_screen`).
    SCREEN_SIGMA_FACTOR = 5.0
    inputs = ('ranges', 'tag_ranges', 'pitches', 'slew')

    def __init__(self, model, sigma=DEFAULT_NOISE.sigma, eta=DEFAULT_NOISE.eta, tag_sigma=None,
                 pitch_sigma=DEFAULT_NOISE.pitch_sigma, slew_sigma=DEFAULT_NOISE.slew_sigma,
                 nlos_fraction=DEFAULT_NOISE.nlos_fraction, nlos_gamma=DEFAULT_NOISE.nlos_gamma,
                 tol=1e-10,
                 max_iter=50, slew_starts=16, screen_iterations=4, lowest_joint=-0.5,
                 search_budget=400, link_bias_std=0.0):
        self.model = model
        self.eta = float(eta)
        self.link_bias = fitted_link_bias(link_bias_std, (model.n_sections, model.n_anchors))
        self.noise = SensorNoise(float(sigma), float(sigma if tag_sigma is None else tag_sigma),
                                 float(pitch_sigma), float(slew_sigma))
        self.nlos = NlosMixture(float(nlos_fraction), float(nlos_gamma))
        #: The judge's share of outliers (``NlosMixture.judged``): learned, or the prior.
        self.outlier_fraction = OUTLIER_FRACTION
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.slew_starts = int(slew_starts)
        self.screen_iterations = int(screen_iterations)
        self.lowest_joint = float(lowest_joint)
        if isinstance(search_budget, bool) or not isinstance(search_budget, (int, np.integer)) \
                or search_budget < 1:
            raise ValueError(f'search_budget: must be an integer >= 1, got {search_budget!r}')
        self.search_budget = int(search_budget)
        self._carry = ([], 0)           # an exhausted search: its best fits, starts screened
        # (Residuals, its ranges' bound losses: the fit's and the judge's)
        self._link_loss = (None, None, None)

    def tune(self, *, sigma, eta, nlos_fraction, nlos_gamma, tag_sigma=None,
             outlier_fraction=None):
        """
        Take new range noise values (learned while running) from the next frame on.

        ``tag_sigma`` None keeps the tag-tag ranges' sigma; ``outlier_fraction``, the
        judge's share of outliers, None keeps it.
        """
        mixture = NlosMixture(float(nlos_fraction), float(nlos_gamma))
        if outlier_fraction is None:
            outlier_fraction = self.outlier_fraction
        mixture.judged(outlier_fraction)            # a share that does not fit raises
        noise = SensorNoise(float(sigma), self.noise.tag_sigma if tag_sigma is None
                            else float(tag_sigma), self.noise.pitch_sigma, self.noise.slew_sigma)
        if not (np.isfinite(eta) and eta >= 0):
            raise ValueError(f'eta: must be a finite number >= 0, got {eta!r}')
        self.noise, self.nlos, self.eta = noise, mixture, float(eta)
        self.outlier_fraction = float(outlier_fraction)
        self._link_loss = (None, None, None)

    def enough_information(self, measurements):
        """
        Judge whether a frame can fix the p + 1 unknowns.

        The tip's pitch is seen only by the tip's ranges or inclinometer.
        """
        tip_seen = (np.isfinite(measurements.ranges[-1]).any()
                    or np.isfinite(measurements.tag_ranges[-1]).any()
                    or np.isfinite(measurements.tag_ranges[:, -1]).any()
                    or np.isfinite(measurements.pitches[-1]))
        return bool(tip_seen) and measurements.count() >= self.model.n_sections + 1

    def reset(self, joints=None):
        """Forget an unfinished search (the warm start is the prior the chain is given)."""
        self._carry = ([], 0)

    @property
    def judged_nlos(self):
        """Return the judge's range model: the NLOS mixture with the outliers' share."""
        return self.nlos.judged(self.outlier_fraction)

    # -- the least-squares problem --------------------------------------------------------
    def losses(self, residuals):
        """Return the frame's ranges' bound losses: the fit's mixture, the judge's (outliers)."""
        if self._link_loss[0] is not residuals:
            sigma = residuals.sigma[:residuals.n_ranged]
            fitting, judging = self.nlos, self.judged_nlos
            bound = fitting.bind(sigma)
            self._link_loss = (residuals, bound,
                               bound if judging is fitting else judging.bind(sigma))
        return self._link_loss[1:]

    def loss(self, scaled, residuals, judged=False):
        """
        Cost, its slope in the scaled residuals, Gauss-Newton weights, NLOS probabilities.

        Ranges follow the NLOS mixture (on their excess, ``-scaled``), with outliers when
        ``judged`` (``NlosMixture.judged``); angles are Gaussian.
        """
        n = residuals.n_ranged                   # ranges come first
        cost, slope = 0.5 * scaled ** 2, scaled.copy()
        blocked = np.zeros_like(scaled)
        cost[:n], excess_slope, blocked[:n] = self.losses(residuals)[judged](-scaled[:n])
        slope[:n] = -excess_slope
        # IRLS curvature slope / residual: 1 for Gaussian rows, small on a blocked link.
        large = np.abs(scaled) > 1.0
        weights = np.ones_like(scaled)
        weights[large] = np.clip(slope[large] / scaled[large], 1e-3, 1.0)
        return float(np.sum(cost)), slope, weights, blocked

    def _evaluate(self, psi, residuals, judged=False):
        """
        Cost at ``psi`` and what a step needs: (cost, (slope, weights, state)).

        A joint below ``lowest_joint`` adds a stiff quadratic penalty: the boom is above
        the ground, which a fit must respect rather than be discarded for.
        """
        scaled, geometry = residuals.residuals(psi)
        cost, slope, weights, _ = self.loss(scaled, residuals, judged)
        heights = geometry[2][:, 2]
        depth = np.maximum(self.lowest_joint - heights, 0.0) / self.GROUND_SIGMA
        return cost + 0.5 * float(depth @ depth), (slope, weights, (geometry, depth, scaled))

    def _normal_equations(self, psi, residuals, slope, weights, state):
        """Gauss-Newton (IRLS) normal matrix and gradient at ``psi``."""
        geometry, depth, _ = state
        jacobian = residuals.jacobian(psi, geometry)
        normal = (jacobian * weights[:, None]).T @ jacobian
        gradient = jacobian.T @ slope
        if depth.any():
            sinking = -self.model.joint_jacobian(psi[0], psi[1:])[depth > 0, 2, :]
            sinking /= self.GROUND_SIGMA
            normal += sinking.T @ sinking
            gradient += sinking.T @ depth[depth > 0]
        return normal, gradient

    def fit(self, psi, residuals, max_iter=None, stall=STALL, also=()):
        """
        Return the Levenberg–Marquardt :class:`Fit` from ``psi`` on a :class:`Residuals`.

        It stops after ``max_iter`` iterations (the chain's own by default), or when an
        accepted step lowered the cost by at most ``stall`` of itself. The cost is the
        judge's (one short range costs a fit at most about 10), comparable across fits:
        :func:`judged_minimum`, with ``also`` (psi each) as its more starts. A screening
        fit (``max_iter`` given) is only its first fit.
        """
        def minimise(start, judged):
            return self._levenberg_marquardt(start, residuals, judged, max_iter, stall)

        n = residuals.n_ranged
        result = judged_minimum(minimise, self.losses(residuals),
                                lambda result: result.state[:n],
                                lambda x: self.cost(x, residuals), psi, also,
                                refit=max_iter is None)
        return Fit(result.x, result.cost, result.iterations, result.converged)

    @staticmethod
    def compiled():
        """Return the module of the compiled fit, or None where the fit runs in numpy."""
        return kernel(KERNEL)

    def _levenberg_marquardt(self, psi, residuals, judged, max_iter, stall):
        """
        Return :func:`levenberg_marquardt`'s result under the fit's or the judge's loss.

        Its ``state`` is the scaled residuals where it stopped. Compiled where numba is
        (``compiled_chain``); the numpy path is the same fit.
        """
        max_iter = self.max_iter if max_iter is None else max_iter
        compiled = self.compiled()
        if compiled is not None:
            terms = compiled.loss_terms(self.losses(residuals)[judged])
            x, cost, (scaled, _), iterations, converged = compiled.fit(
                psi, self.model, residuals, terms, self.lowest_joint, self.GROUND_SIGMA,
                max_iter, self.tol, stall)
            return LevenbergMarquardtResult(x, cost, scaled, iterations, converged)
        result = levenberg_marquardt(
            psi, lambda x: self._evaluate(x, residuals, judged),
            lambda x, parts: self._normal_equations(x, residuals, *parts),
            max_iter=max_iter, tol=self.tol, stall=stall)
        return replace(result, state=result.state[2][2])

    def residuals_of(self, measurements):
        """Return the frame's :class:`Residuals` under this chain's noise (with its own biases)."""
        noise = self.noise
        if self.eta or np.ndim(self.link_bias):
            distances = np.nan_to_num(measurements.ranges)
            noise = replace(noise, range_sigma=np.hypot(
                np.hypot(noise.range_sigma, self.eta * distances), self.link_bias))
        return Residuals(self.model, measurements, noise)

    def refine(self, joints, residuals, max_iter=None, also=()):
        """
        Return the likeliest posture near ``joints`` (p, 3) and its :class:`Fit`.

        Levenberg–Marquardt from the posture's angles on a :class:`Residuals`: where another
        method's answer (CEPP's) or a hypothesis (a tag's ranges left out) settles under
        this chain's loss; ``also``: more postures (p, 3) for :meth:`fit`'s. The posture
        (p, 3) is in canonical angles.
        """
        slew, pitches = angles_from_joints(self.model, joints)
        fit = self.fit(np.r_[slew, pitches], residuals, max_iter,
                       also=[np.r_[angles_from_joints(self.model, other)] for other in also])
        psi = canonical_angles(fit.psi, self.model.pivot_offset)
        return self.model.forward_kinematics(psi[0], psi[1:]), fit

    def refine_links(self, joints, ranges, sigma, masks, rounds):
        """
        Fit the frame from ``joints`` on several subsets of its tag-anchor ranges at once.

        The integrity checks' solution separation: a fit per tag left out, all from the
        estimate (:meth:`fit_links`).

        Parameters
        ----------
        joints : ndarray, shape (p, 3)
            The start, metres.
        ranges : ndarray, shape (p, m)
            Tag-anchor ranges (NaN unmeasured), metres.
        sigma : ndarray, shape (p, m)
            Their standard deviations, metres.
        masks : ndarray of bool, shape (b, p, m)
            The ranges each fit uses.
        rounds : int
            Trial steps per fit.

        Returns
        -------
        postures : ndarray, shape (b, p, 3)
            Where each fit stopped, metres.

        """
        slew, pitches = angles_from_joints(self.model, joints)
        start = np.tile(np.r_[slew, pitches], (len(masks), 1))
        return self.fit_links(start, ranges, sigma, masks, rounds)[0]

    def fit_links(self, psi, ranges, sigma, masks, rounds, judged=False):
        """
        Fit the frame's tag-anchor ranges from many starts at once, each on its own links.

        The chain's loss on the ranges alone (the NLOS mixture, the ground), each start
        its own problem, all side by side (:func:`levenberg_marquardt_batch`).

        Parameters
        ----------
        psi : ndarray, shape (b, p + 1)
            The starts: slew and pitches, radians.
        ranges : ndarray, shape (p, m)
            Tag-anchor ranges (NaN unmeasured), metres.
        sigma : ndarray, shape (p, m)
            Their standard deviations, metres.
        masks : ndarray of bool, shape (b, p, m)
            The ranges each fit uses.
        rounds : int
            Trial steps per fit.
        judged : bool
            Under the judge's loss (``NlosMixture.judged``) instead of the fit's.

        Returns
        -------
        postures : ndarray, shape (b, p, 3)
            Where each fit stopped, metres.
        cost : ndarray, shape (b,)
            The loss there.

        """
        model = self.model
        used = np.asarray(masks, dtype=bool) & np.isfinite(ranges)
        measured = np.where(used, ranges, 0.0)
        link_loss = (self.judged_nlos if judged else self.nlos).bind(sigma)

        def evaluate(psi):
            joints = model.forward_kinematics(psi[:, 0], psi[:, 1:])               # (b, p, 3)
            offset = joints[:, :, None, :] - model.anchors                      # (b, p, m, 3)
            distance = np.linalg.norm(offset, axis=-1)
            excess = np.where(used, (measured - distance) / sigma, 0.0)
            cost, slope, _ = link_loss(excess)
            depth = np.maximum(self.lowest_joint - joints[..., 2], 0.0) / self.GROUND_SIGMA
            total = np.where(used, cost, 0.0).sum(axis=(1, 2)) + 0.5 * np.sum(depth ** 2, 1)
            unit = offset / np.maximum(distance, 1e-12)[..., None]
            return total, (excess, np.where(used, slope, 0.0), unit, depth)

        def normal_equations(psi, state):
            excess, slope, unit, depth = state
            jacobian = model.joint_jacobian(psi[:, 0], psi[:, 1:])           # (b, p, 3, p+1)
            rows = -np.einsum('bkjc,bkcq->bkjq', unit, jacobian) / sigma[..., None]
            # IRLS curvature slope / excess: 1 for Gaussian rows, small on a blocked link.
            large = np.abs(excess) > 1.0
            ratio = np.clip(slope / np.where(large, excess, 1.0), 1e-3, 1.0)
            weights = np.where(used, np.where(large, ratio, 1.0), 0.0)
            normal = np.einsum('bkjq,bkj,bkjr->bqr', rows, weights, rows)
            gradient = np.einsum('bkjq,bkj->bq', rows, slope)
            sinking = jacobian[:, :, 2, :] * ((depth > 0) / self.GROUND_SIGMA)[..., None]
            normal += np.einsum('bkq,bkr->bqr', sinking, sinking)
            gradient -= np.einsum('bkq,bk->bq', sinking, depth)
            return normal, gradient

        psi, cost = levenberg_marquardt_batch(psi, evaluate, normal_equations, rounds=rounds)
        return model.forward_kinematics(psi[:, 0], psi[:, 1:]), cost

    def cost(self, psi, residuals):
        """Return the loss at angles ``psi`` (p + 1,) on a :class:`Residuals`, as :meth:`fit`'s."""
        compiled = self.compiled()
        if compiled is not None:
            return compiled.cost(psi, self.model, residuals,
                                 compiled.loss_terms(self.losses(residuals)[True]),
                                 self.lowest_joint, self.GROUND_SIGMA)
        return self._evaluate(np.asarray(psi, dtype=float), residuals, judged=True)[0]

    # -- starts ---------------------------------------------------------------------------
    def _beam_starts(self, slews, measurements, range_sigma, width=8):
        """Return :func:`grow_chains` for this chain's model, NLOS mixture and ground."""
        return grow_chains(self.model, measurements, range_sigma, self.judged_nlos, slews,
                           self.lowest_joint, width)

    def _tag_loss(self, k, ends, measurements, range_sigma):
        """Approximate NLOS loss of tag ``k``'s measured ranges at candidate joints (..., 3)."""
        return _tag_loss(self.model, self.judged_nlos, k, ends, measurements, range_sigma)

    def _cold_starts(self, measurements, guess, range_sigma, extra=16):
        """Return start angles: the prior's, each slew's best chain, and the next best overall."""
        starts = []
        if guess is not None:
            slew, pitches = angles_from_joints(self.model, guess)
            starts.append(np.r_[slew, pitches])
        slews = np.linspace(-np.pi, np.pi, self.slew_starts, endpoint=False)
        if np.isfinite(measurements.slew):
            slews = np.r_[measurements.slew, slews]
        pitches, cost = self._beam_starts(slews, measurements, range_sigma)
        chosen = np.zeros(cost.shape, bool)
        chosen[:, 0] = True
        others = np.where(chosen, np.inf, cost).ravel()
        runners_up = np.argsort(others)[:extra]
        chosen.flat[runners_up[np.isfinite(others[runners_up])]] = True
        slew_index, beam_index = np.nonzero(chosen)
        starts.extend(np.c_[slews[slew_index], pitches[slew_index, beam_index]])
        return starts

    def tip_alternatives(self, psi, measurements, range_sigma, most=2):
        """
        Return the same posture with the tip section at its other well-fitting pitches.

        The tip hangs from one joint: its ranges alone place it, and with few of them two
        pitches can fit. Returns the local minima of the tip's loss on its circle
        (:func:`~epp_ros.core.model.folds.tip_circle`), best first, other than the current
        pitch.
        """
        valid = np.isfinite(measurements.ranges[-1])
        if not valid.any() or np.isfinite(measurements.pitches[-1]):
            return []
        tip = self.model.n_sections - 1
        hinge = self.model.forward_kinematics(psi[0], psi[1:])[tip - 1] if tip \
            else self.model.pivot(psi[0])
        grid, ends = tip_circle(self.model, hinge, psi[0])
        cost = self._tag_loss(tip, ends, measurements, range_sigma)
        away = np.abs(wrap_angle(grid - psi[-1])) > 3 * (2 * np.pi / grid.size)
        return [np.r_[psi[:-1], grid[i]] for i in tip_minima(cost, away)[:most]]

    def folds(self, psi):
        """Return the same posture with one joint folded the other way (``folded_angles``)."""
        return folded_angles(self.model, psi)

    @staticmethod
    def _reversals(psi):
        """
        Return the same posture with one section pointing the other way (its pitch + pi).

        Its outer joints all move, and the fit re-bends the neighbours: the second fit of a
        section whose two ends have few ranges.
        """
        return [wrap_angle(psi + np.pi * (np.arange(psi.size) == k))
                for k in range(1, psi.size)]

    def _search(self, measurements, residuals, guess, range_sigma, finish=3, rounds=3):
        """
        Global fit from scratch: its :class:`Fit`, and the other fits it tried (psi each).

        Every start takes a few iterations; the best ``finish`` are fitted to convergence.
        From the best, single-joint folds, single-section reversals and the tip's other fits
        are tried until none lowers the cost. The fits that lost are returned too: the
        integrity checks ask whether any fits about as well elsewhere.
        """
        iterations = 0
        screened = []
        coarse = Residuals(self.model, measurements, replace(
            residuals.noise, range_sigma=self.SCREEN_SIGMA_FACTOR * residuals.noise.range_sigma))
        starts = self._cold_starts(measurements, guess, range_sigma)
        carried, resume = self._carry
        # Go on where the last search stopped: its best fits, then the starts it had not tried.
        order = carried + starts[resume:]
        for done, start in enumerate(order):
            if iterations >= self.search_budget:
                self._give_up(screened, resume + max(done - len(carried), 0))
            psi, used = self._screen(start, coarse)
            screened.append((self.cost(psi, residuals), psi))
            iterations += used
        self._carry = ([], 0)
        finished = []
        for _, start in sorted(screened, key=lambda t: t[0])[:finish]:
            fit = self.fit(start, residuals)
            finished.append(fit)
            iterations += fit.iterations
        best = min(finished, key=lambda fit: fit.cost)
        psi, cost, converged = best.psi, best.cost, best.converged
        tried = [psi for _, psi in screened] + [fit.psi for fit in finished]
        for _ in range(rounds):
            improved = False
            for start in (self.folds(psi) + self._reversals(psi)
                          + self.tip_alternatives(psi, measurements, range_sigma)):
                if iterations >= 2 * self.search_budget:    # a fit is in hand: keep it
                    break
                # Screened like the starts: only a move already fitting better is finished.
                trial, trial_cost, used, _ = self.fit(start, residuals,
                                                      max_iter=2 * self.screen_iterations)
                iterations += used
                tried.append(trial)
                if trial_cost < cost - 1e-9:
                    trial, trial_cost, used, converged = self.fit(trial, residuals)
                    iterations += used
                    psi, cost, improved = trial, trial_cost, True
            if not improved:
                break
        return Fit(psi, cost, iterations, converged), tried

    def _screen(self, start, coarse):
        """
        Return where a few iterations from a cold start go (psi), and how many were taken.

        Under the judge's loss on ``coarse``, the frame's residuals at
        ``SCREEN_SIGMA_FACTOR`` times their sigmas: the beam's starts are metres off, and
        there only a range some 20 sigmas off is let go as an outlier. Under the NLOS
        mixture alone, a range metres short would pull every start to the fold that
        explains it before the judge's loss could weigh it.
        """
        result = self._levenberg_marquardt(start, coarse, True, self.screen_iterations, STALL)
        return result.x, result.iterations

    def _give_up(self, screened, resume, keep=3):
        """Stop a search at its budget, keeping its best fits and where to go on from."""
        best = [psi for _, psi in sorted(screened, key=lambda t: t[0])[:keep]]
        self._carry = (best, resume)
        raise SearchExhausted(f'global search stopped at its budget of {self.search_budget} '
                              'iterations; the next frame goes on with it')

    def solve(self, measurements, prior, warm=False):
        """
        Fit one frame.

        Parameters
        ----------
        measurements : Measurements
            The frame.
        prior : ndarray, shape (p, 3), or None
            Warm: the previous posture, fitted from and searched past only when the fit
            is lost. Cold: one more start of the global search.
        warm : bool
            Whether ``prior`` is a warm start (else a cold one).

        """
        residuals = self.residuals_of(measurements)
        noise = residuals.noise
        fit, lost, iterations, others = None, True, 0, []
        if warm and prior is not None:
            slew, pitches = angles_from_joints(self.model, prior)
            fit = self.fit(np.r_[slew, pitches], residuals)
            iterations = fit.iterations
            lost = fit.cost > 12.5 * residuals.size     # worse than 5 sigma RMS per residual
        if lost:
            range_sigma = np.broadcast_to(noise.range_sigma, measurements.ranges.shape)
            found, others = self._search(measurements, residuals, None if warm else prior,
                                         range_sigma)
            iterations += found.iterations
            if fit is None or found.cost < fit.cost:
                fit = found
        psi = canonical_angles(fit.psi, self.model.pivot_offset)
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        info = {'iterations': iterations, 'converged': fit.converged, 'slew': float(psi[0]),
                'pitches': psi[1:].copy(), 'searched': lost,
                # the search's runners-up: the integrity checks ask if they fit as well
                'alternatives': self.model.forward_kinematics(
                    np.array([o[0] for o in others]), np.array([o[1:] for o in others]))
                if others else []}
        return joints, info
