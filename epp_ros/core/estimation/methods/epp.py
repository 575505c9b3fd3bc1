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
The paper's estimators: the posture as a nearest EDM (``core.nedm``) with the anchors known.

- ``EPP1``: the NEDM model in 3-D without the arm-length constraints.
- ``EPP2``: the same with the arm lengths (base-joint 1 included) as equality constraints.
- ``CEPP``: EPP2 in the boom's vertical plane (rank 2) after projecting the ranges.

Each solves one frame from a prior posture (the previous estimate or a cold start), which
supplies the tag-tag entries of G and the embedding's start.

Each is the paper's method by default. Beyond the paper, which weights every range alike
(H = 1), a method may be asked to reweight its tag-anchor links by iteratively reweighted
least squares under the NLOS mixture (``irls_iterations``, ``core.model.nlos``): a link
that the solution leaves much too long (a blocked path) gets a small entry in H and the
frame is solved again. Our field variant of CEPP, with that and more on by default, is
``field_cepp.FieldCEPP``.
"""
from numbers import Integral

from epp_ros.core.model.nlos import NlosMixture, OUTLIER_FRACTION
from epp_ros.core.model.noise import DEFAULT_NOISE, NoiseModel
from epp_ros.core.model.plane import (fit_plane_to_ranges, fit_slew, from_plane, project_ranges,
                                      slew_step, to_plane)
from epp_ros.core.solvers.edm import align_to_known, refine_stress, squared_distances
from epp_ros.core.solvers.nedm import nearest_edm
import numpy as np

__all__ = ['EPP1', 'EPP2', 'CEPP']


def _checked_noise(sigma, eta, nlos_fraction, nlos_gamma):
    """Return the range noise as floats; ValueError naming the argument when it is invalid."""
    noise = NoiseModel(sigma=sigma, eta=eta, nlos_fraction=nlos_fraction, nlos_gamma=nlos_gamma)
    return noise.sigma, noise.eta, NlosMixture(noise.nlos_fraction, noise.nlos_gamma)


class _EDMMethod:
    """
    Shared machinery of the NEDM estimators: build G, H and the fixed set; solve; embed.

    Parameters
    ----------
    model : BoomModel
    prior_weight : float
        Weight in H of the tag-tag entries of G taken from the prior (the paper: 1).
    anchor_weight : float
        Weight of the anchor-anchor entries; inf holds them fixed.
    tol : float
        Stationarity tolerance of the NEDM solver (its relative KKT residual, see
        :func:`~epp_ros.core.solvers.nedm.nearest_edm`).
    max_iter : int
        Its outer iterations at most.
    sigma : float
        Tag-anchor range standard deviation, metres: the unit of the NLOS reweighting.
    eta : float
        Multiplicative range noise: a range r has standard deviation
        ``hypot(sigma, eta r)``.
    nlos_fraction : float
        Prior probability that a link is NLOS; 0 leaves every weight at 1.
    nlos_gamma : float
        Mean NLOS excess, metres.
    irls_iterations : int
        Re-solves with the links reweighted under the NLOS mixture; 0: the paper's H = 1.
    stress_refinement : bool
        After each embedding, move the tags to a local minimum of the stress of the
        unsquared distances the NEDM was given (``edm.refine_stress``, each weighted by its
        entry of H squared, as in the NEDM's objective): the post-processing of the
        authors' EMBED, which applies it where no distance is fixed (their EPP1 and CEPP1).
        Here fixed distances (the section lengths) are held by ``FIXED_STRESS_WEIGHT``, so
        EPP2 and CEPP keep their lengths. Off by default, as in the paper's text.

    """

    rank = 3
    fix_lengths = True
    prior = 'required'          # the tag-tag entries of G come from a prior posture
    inputs = ('ranges', 'tag_ranges')
    #: Stop reweighting when no link's factor in H moves by more than this.
    IRLS_TOL = 0.05
    #: Floor of a link's IRLS weight, as in the chain.
    MIN_WEIGHT = 1e-3
    #: Bounds of a link's noise-model factor in H, relative to the frame's median link.
    NOISE_FACTOR_RANGE = (0.1, 10.0)
    #: Weight the links by the range noise model (``_noise_factors``); False: H = 1.
    noise_weights = False
    #: What the fit adds to each link's sigma for its own bias, metres: 0, or (p, m) (the
    #: field CEPP's, told per link: ``core.model.noise.fitted_link_bias``).
    link_bias = 0.0
    #: Stress weight of a fixed distance in the refinement: holds it to about a thousandth
    #: of the range errors the unit weights leave.
    FIXED_STRESS_WEIGHT = 1e6

    def __init__(self, model, prior_weight=0.0, anchor_weight=np.inf, tol=1e-6, max_iter=500,
                 sigma=DEFAULT_NOISE.sigma, eta=DEFAULT_NOISE.eta,
                 nlos_fraction=DEFAULT_NOISE.nlos_fraction, nlos_gamma=DEFAULT_NOISE.nlos_gamma,
                 irls_iterations=0,
                 stress_refinement=False):
        self.model = model
        self.prior_weight = float(prior_weight)
        self.anchor_weight = float(anchor_weight)
        self.tol = tol
        self.max_iter = max_iter
        if isinstance(irls_iterations, bool) or not isinstance(irls_iterations, Integral) \
                or irls_iterations < 0:
            raise ValueError(f'irls_iterations: must be an integer >= 0, got '
                             f'{irls_iterations!r}')
        self.irls_iterations = int(irls_iterations)
        if not isinstance(stress_refinement, (bool, np.bool_)):
            raise ValueError(f'stress_refinement: must be true or false, got '
                             f'{stress_refinement!r}')
        self.stress_refinement = bool(stress_refinement)
        self.sigma, self.eta, self.nlos = _checked_noise(sigma, eta, nlos_fraction, nlos_gamma)
        #: The judge's share of outliers (``NlosMixture.judged``): learned, or the prior.
        self.outlier_fraction = OUTLIER_FRACTION
        base_anchor = model.base_anchor()
        self._base_anchor = base_anchor
        self._other_anchors = np.array([j for j in range(model.n_anchors) if j != base_anchor],
                                       dtype=int)

    def tune(self, *, sigma=None, eta=None, nlos_fraction=None, nlos_gamma=None,
             outlier_fraction=None):
        """
        Change the range noise the links are reweighted by, from the next frame on.

        Parameters
        ----------
        sigma : float, optional
            Tag-anchor range standard deviation, metres.
        eta : float, optional
            Multiplicative range noise factor.
        nlos_fraction : float, optional
            Prior probability that a link is NLOS, in [0, 1).
        nlos_gamma : float, optional
            Mean NLOS excess, metres.
        outlier_fraction : float, optional
            The judge's share of outliers (``NlosMixture.judged``).

        Those not given keep their values. Raises ValueError naming the argument, leaving
        the noise as it was, when a value is invalid.

        """
        given = {'sigma': sigma, 'eta': eta, 'nlos_fraction': nlos_fraction,
                 'nlos_gamma': nlos_gamma}
        current = {'sigma': self.sigma, 'eta': self.eta, 'nlos_fraction': self.nlos.fraction,
                   'nlos_gamma': self.nlos.gamma}
        noise = {name: current[name] if value is None else value
                 for name, value in given.items()}
        sigma, eta, nlos = _checked_noise(**noise)
        share = self.outlier_fraction if outlier_fraction is None else float(outlier_fraction)
        nlos.judged(share)                          # a share that does not fit raises
        self.sigma, self.eta, self.nlos, self.outlier_fraction = sigma, eta, nlos, share

    def enough_information(self, measurements):
        """Whether the frame's tag-anchor links can determine the posture."""
        valid = np.isfinite(measurements.ranges)
        p = self.model.n_sections
        # Without lengths each tag stands alone: r + 1 ranges, or its mirror image fits too.
        per_tag, total = ((1, (self.rank - 1) * p) if self.fix_lengths
                          else (self.rank + 1, 3 * p))
        return valid.sum(axis=1).min() >= per_tag and valid.sum() >= total

    def reset(self, joints=None):
        """Do nothing: the EDM methods keep no state of their own."""

    def _known_columns(self, ranges):
        """Ranges (p, k) from each tag to the known points: base first, then other anchors."""
        p = self.model.n_sections
        base_column = (ranges[:, self._base_anchor] if self._base_anchor is not None
                       else np.full(p, np.nan))
        return np.column_stack([base_column, ranges[:, self._other_anchors]])

    def _link_weights(self, joints, ranges):
        """
        Return each link's factor in H and whether it looks blocked, for the fit ``joints``.

        The IRLS weight of the NLOS mixture, as the chain's: slope over excess (in sigmas,
        measured range minus fitted distance), clipped, 1 within one sigma. H weights the
        squared-distance residual ``d^2 - delta^2 ~ -2 d e`` and enters the cost squared,
        so the factor is the weight's square root: the cost of a link becomes the paper's
        ``(2 d e)^2`` times the mixture's weight, which is the IRLS step of the mixture
        with the paper's weighting of line-of-sight links kept, and a blocked link's pull
        bounded. (The weight itself would square the downweighting: a 1 m excess at
        sigma 0.1 m would count 1e-4 instead of 1e-2, hardly more robust, and the moderate
        weights of LOS links two sigmas long would drop too.)

        Parameters
        ----------
        joints : ndarray, shape (p, 3)
            The fitted joints, metres.
        ranges : ndarray, shape (p, m)
            Measured tag-anchor ranges, metres, NaN where missing.

        Returns
        -------
        factors : ndarray, shape (p, m)
            In (0, 1], NaN where unmeasured.
        blocked : ndarray of bool, shape (p, m)
            Links more likely NLOS than not.

        """
        sigma = self._range_sigma(ranges)
        measured = np.isfinite(ranges)
        excess = np.where(measured, ranges - self.model.ranges(joints), 0.0) / sigma
        _, slope, nlos = self.nlos.loss(excess, sigma)
        weights = np.ones_like(excess)
        large = np.abs(excess) > 1.0
        weights[large] = np.clip(slope[large] / excess[large], self.MIN_WEIGHT, 1.0)
        return np.where(measured, np.sqrt(weights), np.nan), measured & (nlos > 0.5)

    def _range_sigma(self, ranges):
        """
        Return each range's standard deviation for the fit (p, m), metres.

        ``hypot(sigma, eta r)``, and what is unknown of the link's own bias beyond the
        best-known link's (:attr:`link_bias`, ``core.model.noise.fitted_link_bias``).
        """
        return np.hypot(np.hypot(self.sigma, self.eta * np.nan_to_num(ranges)), self.link_bias)

    def _noise_factors(self, ranges):
        """
        Return each link's factor in H from the range noise model, or 1 (the paper's).

        H weights the residual of a squared distance, ``d^2 - delta^2 ~ 2 d e``, whose
        standard deviation is ``2 d sigma(d)`` with ``sigma(d) = hypot(sigma, eta d)``: the
        paper's H = 1 over-weights long links. The factor is ``1 / (d sigma(d))``, scaled
        so that the frame's median link has 1 (the solver's penalty and tolerances are
        tuned for H ~ 1), and clipped to ``NOISE_FACTOR_RANGE``.

        Parameters
        ----------
        ranges : ndarray, shape (p, m)
            Measured tag-anchor ranges, metres, NaN where missing.

        Returns
        -------
        ndarray, shape (p, m), or float 1.0 without ``noise_weights``

        """
        measured = np.isfinite(ranges)
        if not self.noise_weights or not measured.any():
            return 1.0
        distance = np.maximum(np.where(measured, ranges, 0.0), self.sigma)
        inverse = 1.0 / (distance * self._range_sigma(distance))
        factors = inverse / np.median(inverse[measured])
        return np.where(measured, np.clip(factors, *self.NOISE_FACTOR_RANGE), np.nan)

    def _reweighted(self, solve, ranges, weights=None):
        """
        Solve, then re-solve with the links reweighted, up to ``irls_iterations`` times.

        Parameters
        ----------
        solve : callable
            ``solve(link_weights, start) -> (joints, coords, info)``: the frame with each
            link's H entry multiplied by ``link_weights`` (p, m), started from the solver
            coordinates ``coords`` of the last solution (None: from the prior).
        ranges : ndarray, shape (p, m)
            Measured tag-anchor ranges, metres, NaN where missing.
        weights : ndarray, shape (p, m), optional
            Factors to start from (ones: the paper's H).

        Returns
        -------
        joints : ndarray, shape (p, 3)
        coords : ndarray, shape (p, d)
        info : dict
            The last solve's, with ``iterations`` and ``inner_iterations`` summed over all,
            ``irls_iterations`` (re-solves done) and ``link_weights`` (p, m) when reweighted;
            ``blocked_links`` (p, m) when the last solution's links were judged (the
            second output of :meth:`_link_weights`).

        """
        weights = np.ones(ranges.shape) if weights is None else weights
        noise = self._noise_factors(ranges)
        joints, coords, info = solve(np.nan_to_num(noise * weights), None)
        totals = {'iterations': info['iterations'], 'inner_iterations': info['inner_iterations']}
        done, blocked = 0, None
        while done < self.irls_iterations:
            new, blocked = self._link_weights(joints, ranges)
            if not np.nanmax(np.abs(new - weights), initial=0.0) > self.IRLS_TOL:
                break
            weights, done, blocked = new, done + 1, None
            joints, coords, info = solve(np.nan_to_num(noise * weights), coords)
            for key in totals:
                totals[key] += info[key]
        info.update(totals, irls_iterations=done)
        if blocked is not None:         # the links the last solution's weights call blocked
            info['blocked_links'] = blocked
        if self.irls_iterations:
            info['link_weights'] = np.where(np.isfinite(ranges), weights, np.nan)
        return joints, coords, info

    def _solve_edm(self, known, tag_squared, tag_weights, prior, tag_tag_ranges, start=None,
                   held=None):
        """
        Solve the NEDM for tags given known points (k, d), squared ranges (p, k), prior.

        ``tag_tag_ranges`` (p, p), NaN where not measured, replace the prior's tag-tag
        entries of G with weight 1 (both directions measured: their mean square). The
        solver starts from ``start`` (p, d) when given (a re-solve), else from the prior.
        ``held``, when given, is ``(weights, targets)``, both (p + 1, p + 1) over the pivot
        and the tags (base outward): squared distances held to ``targets`` with those
        weights in H where the weight is > 0 (see ``FieldCEPP._held_pairs``).
        """
        k, p = known.shape[0], prior.shape[0]
        n = k + p
        lengths_sq = self.model.arm_lengths ** 2
        target = squared_distances(np.vstack([known, prior]))
        initial = target if start is None else squared_distances(np.vstack([known, start]))
        target = target.copy()
        weights = np.zeros((n, n))
        fixed = np.zeros((n, n), bool)
        # Known-known distances are fixed (anchor_weight inf, as in the authors' code) or
        # weighted. Fixed, the convex subproblem has no strictly feasible point when the
        # known points outnumber their affine dimension + 1 (always in the plane), and its
        # dual Newton method crawls when started far from feasible (cold starts); weighted,
        # the unequal weights slow the majorization instead. Warm-started, fixed is faster.
        if np.isinf(self.anchor_weight):
            fixed[:k, :k] = True
        else:
            weights[:k, :k] = self.anchor_weight
        tags = slice(k, n)
        measured = np.isfinite(tag_squared)
        target[tags, :k] = np.where(measured, tag_squared, target[tags, :k])
        target[:k, tags] = target[tags, :k].T
        weights[tags, :k] = np.where(measured, tag_weights, 0.0)
        weights[:k, tags] = weights[tags, :k].T
        weights[tags, tags] = self.prior_weight
        measured_sq = tag_tag_ranges ** 2
        both = np.isfinite(measured_sq) & np.isfinite(measured_sq.T)
        measured_sq = np.where(both, 0.5 * (measured_sq + measured_sq.T),
                               np.where(np.isfinite(measured_sq), measured_sq, measured_sq.T))
        tag_measured = np.isfinite(measured_sq)
        target[tags, tags] = np.where(tag_measured, measured_sq, target[tags, tags])
        weights[tags, tags] = np.where(tag_measured, 1.0, self.prior_weight)
        chain = np.r_[0, np.arange(k, n)]                  # base, joint 1, ..., joint p
        if held is not None:
            held_weights, held_targets = held
            rows, cols = np.nonzero(held_weights > 0)
            target[chain[rows], chain[cols]] = held_targets[rows, cols]
            weights[chain[rows], chain[cols]] = held_weights[rows, cols]
        if self.fix_lengths:
            target[chain[:-1], chain[1:]] = target[chain[1:], chain[:-1]] = lengths_sq
            fixed[chain[:-1], chain[1:]] = fixed[chain[1:], chain[:-1]] = True
        result = nearest_edm(target, weights, rank=self.rank, fixed=fixed, initial=initial,
                             tol=self.tol, max_iter=self.max_iter)
        aligned = align_to_known(result.points, np.arange(k), known, pivot=0)
        info = {'iterations': result.iterations, 'inner_iterations': result.inner_iterations,
                'rank_error': result.rank_error, 'kkt_residual': result.kkt_residual,
                'converged': result.converged}
        if self.stress_refinement:
            aligned, info['refinement_evaluations'] = refine_stress(
                np.vstack([known, aligned[tags]]), np.arange(k, n), np.sqrt(target),
                np.where(fixed, self.FIXED_STRESS_WEIGHT, weights ** 2))
        return aligned[tags], info


class EPP1(_EDMMethod):
    """NEDM posture estimate in 3-D without arm-length constraints (the paper's EPP1)."""

    fix_lengths = False
    holds_chain = False         # joints anywhere in space: each one's own bound applies

    def solve(self, measurements, prior, warm=False):
        # A pivot off the slew axis is placed at the prior's slew.
        pivot = self.model.pivot_of(prior)
        known = np.vstack([pivot, self.model.anchors[self._other_anchors]])
        squared = self._known_columns(measurements.ranges) ** 2

        def solve(link_weights, start):
            joints, info = self._solve_edm(known, squared, self._known_columns(link_weights),
                                           prior, measurements.tag_ranges, start)
            return joints, joints, info

        joints, _, info = self._reweighted(solve, measurements.ranges)
        info.pop('blocked_links', None)
        return joints, info


class EPP2(EPP1):
    """NEDM posture estimate in 3-D with fixed arm lengths (the paper's EPP2)."""

    fix_lengths = True
    free_per_joint = 2          # its three coordinates, its arm length held


class CEPP(_EDMMethod):
    """
    EPP2 in the boom's vertical plane (the paper's CEPP).

    As published: the plane is the previous estimate's (a cold frame, which the paper does
    not cover, has its plane fitted to its ranges), the ranges
    are projected into it exactly (clipped where noise makes that impossible, the clipped
    links down-weighted by ``clip_weight``), every range weighs alike (H = 1) and every
    tag needs a range. Options, off by default:

    - ``predict_slew``: fit the plane to this frame's 3-D ranges first (Gauss-Newton on
      the slew and free in-plane tags, from the prior), since the paper's plane never
      turns with a slewing boom; ``slew_iterations`` more times the slew is then refined
      from the solution and the plane problem re-solved;
    - ``irls_iterations``: discount NLOS links (see ``_EDMMethod``); the plane is then
      fitted without the links that look blocked.

    Our field variant, with these on and more, is :class:`FieldCEPP` (method ``cepp``).
    """

    rank = 2
    holds_chain = True          # lengths and the vertical plane: the chain's bound applies
    #: Gauss-Newton steps when predicting the slew: from last frame's plane, three converge
    #: it far below what the ranges resolve.
    PREDICTION_STEPS = 3

    def __init__(self, model, clip_weight=0.1, predict_slew=False, slew_iterations=0,
                 slew_tol=1e-6, **options):
        super().__init__(model, **options)
        self.clip_weight = float(clip_weight)
        if not isinstance(predict_slew, (bool, np.bool_)):
            raise ValueError(f'predict_slew: must be true or false, got {predict_slew!r}')
        self.predict_slew = bool(predict_slew)
        self.slew_iterations = int(slew_iterations)
        if self.slew_iterations < 0:
            raise ValueError(f'slew_iterations: must be >= 0, got {slew_iterations}')
        self.slew_tol = float(slew_tol)

    def solve(self, measurements, prior, warm=False):
        """Estimate one frame from ``prior``: the last posture (``warm``) or a cold guess."""
        return self._solve_from(measurements, prior, warm)

    def _held_pairs(self, ranges, prior):
        """Return None: the paper holds nothing of the prior (a silent tag fails the frame)."""
        return None

    def _kept_folds(self, coords, prior_2d, pivot, ranges):
        """Return the plane solution ``coords`` (p, 2) and the joints refolded (none here)."""
        return coords, 0

    def _solve_in_plane(self, measurements, prior, slew, weights=None, warm=True):
        """
        Solve the plane NEDM at ``slew``, reweighting the links; (joints, coords, info).

        ``weights`` (p, m): the links' factors in H to start from (ones: the paper's).
        ``warm``: the prior is a posture (a cold start's guess has no bends to hold).
        """
        ranges = measurements.ranges
        base = self.model.base
        squared, clipped = project_ranges(ranges, self.model.anchors, base, slew)
        clip_factor = np.where(clipped, self.clip_weight, 1.0)
        anchors_2d = to_plane(self.model.anchors, base, slew)
        known = np.vstack([[self.model.pivot_offset, base[2]], anchors_2d[self._other_anchors]])
        columns = self._known_columns(squared)
        prior_2d = to_plane(prior, base, slew)
        held = self._held_pairs(ranges, prior) if warm else None

        def solve(link_weights, start):
            # Two tags in the plane are as far apart in it as in space.
            coords, info = self._solve_edm(known, columns,
                                           self._known_columns(clip_factor * link_weights),
                                           prior_2d, measurements.tag_ranges, start, held)
            if held is not None:
                coords, info['kept_folds'] = self._kept_folds(coords, prior_2d, known[0],
                                                              ranges)
            return from_plane(coords, base, slew), coords, info

        return self._reweighted(solve, ranges, weights)

    def _predicted_slew(self, ranges, prior, warm=True):
        """
        Slew of the plane to solve in, and the links' factors in H to start from (or None).

        Without ``predict_slew`` the plane is the prior's, as published, when the prior is
        the last posture (``warm``); a cold frame has none, and the paper does not say how
        the first frame is found, so its plane is fitted to its ranges. When reweighting,
        the plane is fitted again without the links its fit finds more likely blocked than
        not, up to ``irls_iterations`` times: one 1 m NLOS excess tilts an unweighted fit
        by degrees, metres at the tip, which no weighting in the plane
        can undo. The fit's weights then start the plane's reweighting.
        """
        base = self.model.base
        slew = fit_slew(prior, base)
        if warm and not self.predict_slew:
            return slew, None
        coords, weights, dropped = to_plane(prior, base, slew), None, np.zeros(ranges.shape, bool)
        for attempt in range(self.irls_iterations + 1):
            predicted, fitted = fit_plane_to_ranges(
                coords, np.where(dropped, np.nan, ranges), self.model.anchors, base, slew,
                (self.model.pivot_offset, base[2]), self.model.arm_lengths,
                self.PREDICTION_STEPS, self.slew_tol)
            if not np.isfinite(predicted):
                break
            slew, coords = predicted, fitted
            if attempt == self.irls_iterations or not np.all(np.isfinite(coords)):
                break
            weights, blocked = self._link_weights(from_plane(coords, base, slew), ranges)
            if np.array_equal(blocked, dropped):
                break
            dropped = blocked
        return slew, weights

    def _solve_from(self, measurements, prior, warm):
        """Solve the frame from ``prior``: predict the plane, solve in it; (joints, info)."""
        ranges = measurements.ranges
        slew, weights = self._predicted_slew(ranges, prior, warm)
        totals = {'iterations': 0, 'inner_iterations': 0, 'irls_iterations': 0}
        for attempt in range(self.slew_iterations + 1):
            # Each plane starts from the last one's weights: its blocked links are known.
            joints, coords, info = self._solve_in_plane(measurements, prior, slew, weights,
                                                        warm)
            blocked = info.pop('blocked_links', None)
            weights = info.get('link_weights')
            for key in totals:
                totals[key] += info[key]
            if attempt == self.slew_iterations:
                break
            if self.irls_iterations:            # the slew from the links that look clear
                if blocked is None:
                    blocked = self._link_weights(joints, measurements.ranges)[1]
                ranges = np.where(blocked, np.nan, measurements.ranges)
            step = slew_step(coords, ranges, self.model.anchors, self.model.base, slew)
            if abs(step) <= self.slew_tol:
                break
            slew, prior = slew + step, joints
        info.update(totals, slew=float(np.mod(slew + np.pi, 2 * np.pi) - np.pi))
        return joints, info
