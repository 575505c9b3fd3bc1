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

Beyond the paper, which weights every range alike (H = 1), a method may reweight its
tag-anchor links by iteratively reweighted least squares under the NLOS mixture
(``core.nlos``): a link that the solution leaves much too long (a blocked path) gets a
small entry in H and the frame is solved again. CEPP does so by default; EPP1 and EPP2 and
``irls_iterations=0`` are the paper's methods.
"""
from numbers import Integral, Real

import numpy as np

from .edm import align_to_known, squared_distances
from .nedm import nearest_edm
from .nlos import NlosMixture
from .plane import fit_plane_to_ranges, fit_slew, from_plane, project_ranges, slew_step, to_plane

__all__ = ['EPP1', 'EPP2', 'CEPP']


def _checked_noise(sigma, eta, nlos_fraction, nlos_gamma):
    """Return the range noise as floats; ValueError naming the argument when it is invalid."""
    values = {'sigma': sigma, 'eta': eta, 'nlos_fraction': nlos_fraction,
              'nlos_gamma': nlos_gamma}
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, Real) or not np.isfinite(value):
            raise ValueError(f'{name}: must be a finite number, got {value!r}')
    for name in ('sigma', 'eta'):
        if values[name] < 0:
            raise ValueError(f'{name}: must be >= 0, got {values[name]!r}')
    if sigma == eta == 0:
        raise ValueError('sigma: must be > 0 when eta is 0')
    nlos = NlosMixture(float(nlos_fraction), float(nlos_gamma))   # names its own argument
    return float(sigma), float(eta), nlos


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
        Relative tolerance of the NEDM solver.
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

    """

    rank = 3
    fix_lengths = True
    prior = 'required'          # the tag-tag entries of G come from a prior posture
    inputs = ('ranges', 'tag_ranges')
    #: Stop reweighting when no link's factor in H moves by more than this.
    IRLS_TOL = 0.05
    #: Floor of a link's IRLS weight, as in the chain.
    MIN_WEIGHT = 1e-3

    def __init__(self, model, prior_weight=0.0, anchor_weight=np.inf, tol=1e-6, max_iter=500,
                 sigma=0.1, eta=0.0, nlos_fraction=0.1, nlos_gamma=1.0, irls_iterations=0):
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
        self.sigma, self.eta, self.nlos = _checked_noise(sigma, eta, nlos_fraction, nlos_gamma)
        base_anchor = model.base_anchor()
        self._base_anchor = base_anchor
        self._other_anchors = np.array([j for j in range(model.n_anchors) if j != base_anchor],
                                       dtype=int)

    def tune(self, *, sigma=None, eta=None, nlos_fraction=None, nlos_gamma=None):
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

        Those not given keep their values. Raises ValueError naming the argument, leaving
        the noise as it was, when a value is invalid.

        """
        given = {'sigma': sigma, 'eta': eta, 'nlos_fraction': nlos_fraction,
                 'nlos_gamma': nlos_gamma}
        current = {'sigma': self.sigma, 'eta': self.eta, 'nlos_fraction': self.nlos.fraction,
                   'nlos_gamma': self.nlos.gamma}
        noise = {name: current[name] if value is None else value
                 for name, value in given.items()}
        self.sigma, self.eta, self.nlos = _checked_noise(**noise)

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
        sigma = np.hypot(self.sigma, self.eta * np.nan_to_num(ranges))
        measured = np.isfinite(ranges)
        excess = np.where(measured, ranges - self.model.ranges(joints), 0.0) / sigma
        _, slope, nlos = self.nlos.loss(excess, sigma)
        weights = np.ones_like(excess)
        large = np.abs(excess) > 1.0
        weights[large] = np.clip(slope[large] / excess[large], self.MIN_WEIGHT, 1.0)
        return np.where(measured, np.sqrt(weights), np.nan), measured & (nlos > 0.5)

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
            ``irls_iterations`` (re-solves done) and ``link_weights`` (p, m) when reweighted.

        """
        weights = np.ones(ranges.shape) if weights is None else weights
        joints, coords, info = solve(np.nan_to_num(weights), None)
        totals = {'iterations': info['iterations'], 'inner_iterations': info['inner_iterations']}
        done = 0
        while done < self.irls_iterations:
            new, _ = self._link_weights(joints, ranges)
            if not np.nanmax(np.abs(new - weights), initial=0.0) > self.IRLS_TOL:
                break
            weights, done = new, done + 1
            joints, coords, info = solve(np.nan_to_num(weights), coords)
            for key in totals:
                totals[key] += info[key]
        info.update(totals, irls_iterations=done)
        if self.irls_iterations:
            info['link_weights'] = np.where(np.isfinite(ranges), weights, np.nan)
        return joints, coords, info

    def _solve_edm(self, known, tag_squared, tag_weights, prior, tag_tag_ranges, start=None):
        """
        Solve the NEDM for tags given known points (k, d), squared ranges (p, k), prior.

        ``tag_tag_ranges`` (p, p), NaN where not measured, replace the prior's tag-tag
        entries of G with weight 1 (both directions measured: their mean square). The
        solver starts from ``start`` (p, d) when given (a re-solve), else from the prior.
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
        if self.fix_lengths:
            chain = np.r_[0, np.arange(k, n)]              # base, joint 1, ..., joint p
            target[chain[:-1], chain[1:]] = target[chain[1:], chain[:-1]] = lengths_sq
            fixed[chain[:-1], chain[1:]] = fixed[chain[1:], chain[:-1]] = True
        result = nearest_edm(target, weights, rank=self.rank, fixed=fixed, initial=initial,
                             tol=self.tol, max_iter=self.max_iter)
        aligned = align_to_known(result.points, np.arange(k), known, pivot=0)
        info = {'iterations': result.iterations, 'inner_iterations': result.inner_iterations,
                'rank_error': result.rank_error, 'kkt_residual': result.kkt_residual,
                'converged': result.converged}
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
        return joints, info


class EPP2(EPP1):
    """NEDM posture estimate in 3-D with fixed arm lengths (the paper's EPP2)."""

    fix_lengths = True


class CEPP(_EDMMethod):
    """
    EPP2 in the boom's vertical plane (the paper's CEPP).

    The paper takes the plane from the prior (previous estimate or cold start), so the plane
    never turns. Beyond the paper, the plane is first fitted to this frame's 3-D ranges
    (``predict_slew``: Gauss-Newton on the slew and free in-plane tags, from the prior);
    ``slew_iterations`` more times the slew is then refined from the solution and the plane
    problem re-solved.

    Also beyond the paper, by default, NLOS links are discounted (``irls_iterations``, see
    ``_EDMMethod``): the plane is fitted without the links that look blocked, and the plane
    problem re-solved with each link's entry of H times its IRLS weight's square root (times
    ``clip_weight`` where the projection was clipped). ``irls_iterations=0`` is the paper's
    CEPP, with the plane from all the ranges and H = 1.
    """

    rank = 2
    holds_chain = True          # lengths and the vertical plane: the chain's bound applies
    #: Gauss-Newton steps when predicting the slew: from last frame's plane, three converge
    #: it far below what the ranges resolve.
    PREDICTION_STEPS = 3
    #: Default re-solves with the links reweighted for NLOS (0: the paper's H = 1).
    IRLS_ITERATIONS = 2

    def __init__(self, model, clip_weight=0.1, predict_slew=True, slew_iterations=0,
                 slew_tol=1e-6, irls_iterations=IRLS_ITERATIONS, **options):
        super().__init__(model, irls_iterations=irls_iterations, **options)
        self.clip_weight = float(clip_weight)
        if not isinstance(predict_slew, (bool, np.bool_)):
            raise ValueError(f'predict_slew: must be true or false, got {predict_slew!r}')
        self.predict_slew = bool(predict_slew)
        self.slew_iterations = int(slew_iterations)
        if self.slew_iterations < 0:
            raise ValueError(f'slew_iterations: must be >= 0, got {slew_iterations}')
        self.slew_tol = float(slew_tol)

    def _solve_in_plane(self, measurements, prior, slew, weights=None):
        """
        Solve the plane NEDM at ``slew``, reweighting the links; (joints, coords, info).

        ``weights`` (p, m): the links' factors in H to start from (ones: the paper's).
        """
        ranges = measurements.ranges
        base = self.model.base
        squared, clipped = project_ranges(ranges, self.model.anchors, base, slew)
        clip_factor = np.where(clipped, self.clip_weight, 1.0)
        anchors_2d = to_plane(self.model.anchors, base, slew)
        known = np.vstack([[self.model.pivot_offset, base[2]], anchors_2d[self._other_anchors]])
        columns = self._known_columns(squared)
        prior_2d = to_plane(prior, base, slew)

        def solve(link_weights, start):
            # Two tags in the plane are as far apart in it as in space.
            coords, info = self._solve_edm(known, columns,
                                           self._known_columns(clip_factor * link_weights),
                                           prior_2d, measurements.tag_ranges, start)
            return from_plane(coords, base, slew), coords, info

        return self._reweighted(solve, ranges, weights)

    def _predicted_slew(self, ranges, prior):
        """
        Slew of the plane to solve in, and the links' factors in H to start from (or None).

        When reweighting, the plane is fitted again without the links its fit finds more
        likely blocked than not, up to ``irls_iterations`` times: one 1 m NLOS excess tilts
        an unweighted fit by degrees, metres at the tip, which no weighting in the plane
        can undo. The fit's weights then start the plane's reweighting.
        """
        base = self.model.base
        slew = fit_slew(prior, base)
        if not self.predict_slew:
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

    def solve(self, measurements, prior, warm=False):
        ranges = measurements.ranges
        slew, weights = self._predicted_slew(ranges, prior)
        totals = {'iterations': 0, 'inner_iterations': 0, 'irls_iterations': 0}
        for attempt in range(self.slew_iterations + 1):
            # Each plane starts from the last one's weights: its blocked links are known.
            joints, coords, info = self._solve_in_plane(measurements, prior, slew, weights)
            weights = info.get('link_weights')
            for key in totals:
                totals[key] += info[key]
            if attempt == self.slew_iterations:
                break
            if self.irls_iterations:            # the slew from the links that look clear
                ranges = np.where(self._link_weights(joints, measurements.ranges)[1], np.nan,
                                  measurements.ranges)
            step = slew_step(coords, ranges, self.model.anchors, self.model.base, slew)
            if abs(step) <= self.slew_tol:
                break
            slew, prior = slew + step, joints
        info.update(totals, slew=float(np.mod(slew + np.pi, 2 * np.pi) - np.pi))
        return joints, info
