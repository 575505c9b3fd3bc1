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
Our field CEPP (method ``cepp``, the node's default): the paper's CEPP with what a pump needs.

The paper's CEPP (:class:`~epp_ros.core.estimation.methods.epp.CEPP`, method
``cepp_paper``) weighs every range alike, takes its plane from the last posture, refuses a
frame with a silent tag and trusts its warm start. On a slewing boom with blocked links and
silent tags each of those costs metres (``docs/methods.md``). Each departure is an option
of its own, on by default:

- ``predict_slew`` and ``irls_iterations`` (2): the paper class's options, turned on;
- ``noise_weights``: each link's entry of H is also ``1 / (d sigma(d))`` of the range
  noise model (``sigma(d) = hypot(sigma, eta d)``, as ``tune`` sets it), relative to
  the frame's median link, since H weights squared distances (``_noise_factors``);
- ``silent_weight``: a tag with no range this frame keeps the prior's bends at and next
  to its joint (those squared distances enter G with this weight; 0: the frame is
  refused), and a silent joint between heard ones keeps the prior's fold;
- ``cold_search``: a cold frame is solved from the best chains of a beam search over
  slews and pitches as well as from the prior, the lowest NLOS-mixture loss kept;
- ``fold_search``: a warm frame is solved again from its joints' other folds and its
  tip's other pitches where their own ranges prefer them, kept on a clear win;
- ``polish``: the answer is finished where the frame's NLOS-mixture likelihood peaks
  near it (the chain's Levenberg–Marquardt over the p + 1 angles, on the same ranges).
  The plane solution weighs squared distances and fixes the slew before the pitches;
  under blocked links it can stop degrees from the likeliest posture, and the integrity
  checks, which weigh rivals by that likelihood, must be given its peak. Not with a
  silent tag: the prior's bends hold what the frame's likelihood leaves free.

Fits the searches found elsewhere are returned as ``alternatives`` for the integrity checks.
"""
from numbers import Real

from epp_ros.core.estimation.methods.chain import canonical_angles, ChainMethod, grow_chains, \
    SearchExhausted
from epp_ros.core.estimation.methods.epp import CEPP
from epp_ros.core.model.folds import fold_alternatives, keep_folds, tip_circle, tip_minima
from epp_ros.core.model.measurements import Measurements
from epp_ros.core.model.noise import fitted_link_bias
from epp_ros.core.model.plane import fit_slew
from epp_ros.core.solvers.edm import squared_distances
import numpy as np

__all__ = ['FieldCEPP']


def _switch(name, value):
    """Return ``value`` as a bool; ValueError naming the option when it is not one."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f'{name}: must be true or false, got {value!r}')
    return bool(value)


def _finite(name, value, least=-np.inf):
    """Return ``value`` as a float; ValueError naming the option when not finite and >= least."""
    if isinstance(value, bool) or not isinstance(value, Real) or not np.isfinite(value) \
            or value < least:
        bound = '' if least == -np.inf else f' >= {least:g}'
        raise ValueError(f'{name}: must be a finite number{bound}, got {value!r}')
    return float(value)


class FieldCEPP(CEPP):
    """
    The paper's CEPP with the field's departures (see the module), each one an option.

    Parameters
    ----------
    model : BoomModel
    predict_slew : bool
        Fit the plane to the frame's ranges (the paper: the prior's plane).
    irls_iterations : int
        Re-solves with the links reweighted under the NLOS mixture (the paper: 0).
    noise_weights, cold_search, fold_search, polish : bool
        See the module.
    silent_weight : float
        Weight in H of the prior's bends next to a silent tag (0: the frame is refused).
    lowest_joint : float
        No joint is below this height, metres: a search's fit below it is not kept.
    link_bias_std : float or array_like, shape (p, m)
        What is unknown of each link's own bias, metres: per link, H and the losses weigh
        each range by it (``core.model.noise.fitted_link_bias``); one number changes no
        weight.
    **options
        Of :class:`CEPP` and its base (``sigma``, ``eta``, ``nlos_*``, ``tol``, ...).

    """

    #: Default re-solves with the links reweighted for NLOS.
    IRLS_ITERATIONS = 2
    #: Cold search: slews and pitches of the beam search, and its chains solved from.
    SEARCH_SLEWS = 24
    SEARCH_PITCHES = 36
    SEARCH_STARTS = 3
    #: Cold search: trial steps of each slew's chain climbing the likelihood for the
    #: integrity checks, and the other peaks kept at most (:meth:`_screened_peaks`).
    SCREEN_ROUNDS = 8
    SCREEN_PEAKS = 8
    #: A cold search's other fit further than this from the best (metres) is an alternative;
    #: a start of the search nearer than ``SAME_START`` to a fit found is not solved from.
    ALTERNATIVE_DISTANCE = 0.5
    SAME_START = 2.0
    #: Fold search: how much lower a folded joint's own loss must be to solve from it, how
    #: much lower the frame's loss must be to keep that fit (nats of the NLOS mixture),
    #: and the starts tried at most.
    FOLD_MARGIN = 1.0
    FOLD_GAIN = 10.0
    FOLD_STARTS = 2
    #: Default weight in H of the prior's bends next to a silent tag.
    SILENT_WEIGHT = 1.0
    #: Levenberg–Marquardt iterations of the polish at most (from a plane solution it
    #: converges in a few).
    POLISH_ITERATIONS = 20

    def __init__(self, model, predict_slew=True, irls_iterations=IRLS_ITERATIONS,
                 noise_weights=True, silent_weight=SILENT_WEIGHT, cold_search=True,
                 fold_search=True, polish=True, lowest_joint=-0.5, link_bias_std=0.0,
                 **options):
        super().__init__(model, predict_slew=predict_slew, irls_iterations=irls_iterations,
                         **options)
        self.noise_weights = _switch('noise_weights', noise_weights)
        self.cold_search = _switch('cold_search', cold_search)
        self.fold_search = _switch('fold_search', fold_search)
        self.polish = _switch('polish', polish)
        self.silent_weight = _finite('silent_weight', silent_weight, least=0.0)
        self.lowest_joint = _finite('lowest_joint', lowest_joint)
        self.link_bias = fitted_link_bias(link_bias_std, (model.n_sections, model.n_anchors))
        self._finish = ChainMethod(model, self.sigma, self.eta,
                                   nlos_fraction=self.nlos.fraction,
                                   nlos_gamma=self.nlos.gamma, lowest_joint=self.lowest_joint,
                                   max_iter=self.POLISH_ITERATIONS, link_bias_std=link_bias_std)

    def tune(self, **noise):
        """Change the range noise (see the base's ``tune``); the polish follows it."""
        super().tune(**noise)
        self._finish.tune(sigma=self.sigma, eta=self.eta, nlos_fraction=self.nlos.fraction,
                          nlos_gamma=self.nlos.gamma, outlier_fraction=self.outlier_fraction)

    def _kept_folds(self, coords, prior_2d, pivot, ranges):
        """Return ``coords`` (p, 2) with each silent joint at the prior's fold, and how many."""
        coords, folded = keep_folds(coords, prior_2d, pivot, ~np.isfinite(ranges).any(axis=1))
        return coords, int(folded.sum())

    def enough_information(self, measurements):
        """
        Judge whether the frame's tag-anchor links can determine the posture.

        With ``silent_weight`` a silent tag (no range this frame) is held at the prior's
        bends, so that the others still give the posture: the frame needs ranges on two
        tags and ``p`` in all (one tag alone would leave the boom the prior's shape swung
        about its joint). The integrity checks judge what a silent joint is then worth.
        """
        if not self.silent_weight:
            return super().enough_information(measurements)
        valid = np.isfinite(measurements.ranges)
        heard = int(valid.any(axis=1).sum())
        return heard >= min(2, self.model.n_sections) and valid.sum() >= self.model.n_sections

    def _held_pairs(self, ranges, prior):
        """
        Weights and squared targets holding the prior's bends next to silent tags, or None.

        A tag with no range this frame is placed only by the section lengths: between two
        heard neighbours it may fold either way, at the tip or next to another silent tag
        it may swing freely. Its distance, in the prior, to the pivot or tag two along the
        chain (the bend at the joint between them) is then a target in G of weight
        ``silent_weight``: what the frame does not determine keeps the prior's shape, and
        what it does (a heard neighbour) is barely pulled.

        Parameters
        ----------
        ranges : ndarray, shape (p, m)
            Measured tag-anchor ranges, metres, NaN where missing.
        prior : ndarray, shape (p, 3)
            The prior posture, metres.

        Returns
        -------
        weights, targets : ndarray, shape (p + 1, p + 1), or None
            Over the pivot and the tags, base outward; the weights 0 where not held.

        """
        silent = ~np.isfinite(ranges).any(axis=1)
        if not self.silent_weight or not silent.any():
            return None
        chain = np.vstack([self.model.pivot_of(prior), prior])
        targets = squared_distances(chain)
        hold = np.r_[False, silent]                 # the pivot is never silent
        weights = np.zeros(targets.shape)
        ends = np.arange(targets.shape[0] - 2)
        held = hold[ends] | hold[ends + 1] | hold[ends + 2]     # a bend at or next to one
        weights[ends[held], ends[held] + 2] = self.silent_weight
        weights = np.maximum(weights, weights.T)
        return weights, targets

    def solve(self, measurements, prior, warm=False):
        """
        Estimate one frame from ``prior``: the last posture (``warm``) or a cold guess.

        Warm, with ``fold_search``, the fit's other folds are tried (:meth:`_refolded`).
        Cold, with ``cold_search``, the frame is also solved from the best chains of a
        beam search over slews and pitches (``chain.grow_chains``), and the fit with the
        lowest NLOS-mixture loss of its ranges kept; the others that land elsewhere are
        returned as ``alternatives`` for the integrity checks. Then, with ``polish``,
        the fit kept is finished at the likelihood's peak near it.
        """
        joints, info = self._searched(measurements, prior, warm)
        return self._polished(measurements, joints, info, prior if warm else None)

    def _polished(self, measurements, joints, info, prior=None):
        """
        Return the fit finished at the likelihood's peak near it (``polish``).

        Or near ``prior`` (the last posture), where the judge likes that better: CEPP's
        weights let no range go, and one no noise explains can pull its fit to another fold.
        """
        silent = ~np.isfinite(measurements.ranges).any(axis=1)
        if not self.polish or silent.any() or not np.all(np.isfinite(joints)):
            return joints, info
        polished, fit = self._finish.refine(joints,
                                            self._finish.residuals_of(self._ranged(measurements)),
                                            also=() if prior is None else (prior,))
        if not np.all(np.isfinite(polished)):
            return joints, info
        slew = canonical_angles(fit.psi, self.model.pivot_offset)[0]     # the polished's
        return polished, dict(info, slew=float(slew), polish_iterations=fit.iterations)

    def _ranged(self, measurements):
        """Return the frame's ranges alone (what CEPP uses), as ``Measurements``."""
        return Measurements(measurements.ranges, measurements.tag_ranges,
                            np.full(self.model.n_sections, np.nan), np.nan)

    def _searched(self, measurements, prior, warm):
        """Return :meth:`solve`'s fit before the polish."""
        joints, info = self._solve_from(measurements, prior, warm)
        if warm or not self.cold_search:
            return self._refolded(measurements, joints, info) if warm else (joints, info)
        fits = [(self._fit_cost(joints, measurements.ranges), joints, info)]
        iterations = dict.fromkeys(('iterations', 'inner_iterations'), 0)
        beam = self._beam(measurements.ranges)
        for start in [None] + self._cold_starts(measurements.ranges, beam):
            if start is not None and any(np.abs(start - fit[1]).max() < self.SAME_START
                                         for fit in fits):
                continue                # a start near a fit found ends there too
            found, found_info = (joints, info) if start is None else \
                self._solve_from(measurements, start, False)
            for key in iterations:
                iterations[key] += found_info[key]
            # A fit near one already found is the same minimum: the prior's is kept.
            if all(np.abs(found - fit[1]).max() > self.ALTERNATIVE_DISTANCE for fit in fits):
                fits.append((self._fit_cost(found, measurements.ranges), found, found_info))
        searched = self._chain_searched(measurements) if self.polish else None
        if searched is not None and all(np.abs(searched - fit[1]).max() >
                                        self.ALTERNATIVE_DISTANCE for fit in fits):
            fits.append((self._fit_cost(searched, measurements.ranges), searched,
                         dict(fits[0][2], chain_search=True)))
        _, joints, info = min(fits, key=lambda fit: fit[0])     # the first of equals
        info = dict(info, searched=True, **iterations)
        others = [other for _, other, _ in fits if other is not joints]
        info['alternatives'] = others + self._screened_peaks(
            measurements.ranges, beam, [joints] + others)
        return joints, info

    def _refolded(self, measurements, joints, info):
        """
        Try the warm fit's joints at their other folds, and its tip at its other pitches.

        A warm start follows the boom into the nearest minimum: after an abrupt move a
        joint can stay folded the wrong way, or the tip at the wrong pitch, for many
        frames. Where a joint's own ranges fit such a position better than its fitted one
        (by ``FOLD_MARGIN`` of their loss), the frame is solved again from there, and that
        fit kept when the loss of all the frame's ranges is lower by ``FOLD_GAIN``: a
        clear win, as under persistent NLOS a wrong fold can fit a frame slightly better
        and the warm start is the better guess (``fold_search``). The fit given up is
        returned as an alternative for the integrity checks.
        """
        if not self.fold_search:
            return joints, info
        ranges = measurements.ranges
        starts = self._fold_starts(joints, ranges)
        if not starts:
            return joints, info
        best = (self._fit_cost(joints, ranges), joints, info)
        others = []
        for start in starts:
            found, found_info = self._solve_from(measurements, start, True)
            info['iterations'] += found_info['iterations']
            info['inner_iterations'] += found_info['inner_iterations']
            cost = self._fit_cost(found, ranges)
            if cost < best[0] - self.FOLD_GAIN:
                others.append(best[1])
                best = (cost, found, found_info)
            else:
                others.append(found)
        if best[1] is joints:
            return joints, info
        _, joints, found_info = best
        found_info = dict(found_info, iterations=info['iterations'],
                          inner_iterations=info['inner_iterations'], refolded=True)
        found_info['alternatives'] = [other for other in others
                                      if np.abs(other - joints).max() > self.ALTERNATIVE_DISTANCE]
        return joints, found_info

    def _tag_losses(self, points, ranges, sigma):
        """Return the judge's loss of q tags' ranges (q, m) at points (..., q, 3)."""
        loss = self._finish.judged_nlos.bind(sigma)
        return loss.at_points(points, ranges, self.model.anchors)     # 0: unheard

    def _fold_starts(self, joints, ranges):
        """
        Return the fit with one heard joint folded or the tip turned, where it fits better.

        At most ``FOLD_STARTS``, the largest gains first (``core.model.folds``).
        """
        p = self.model.n_sections
        sigma = self._range_sigma(ranges)
        heard = np.isfinite(ranges).any(axis=1)
        folded = fold_alternatives(self.model, joints)
        fitted, refolded = self._tag_losses(np.stack([joints[:-1], folded]), ranges[:-1],
                                            sigma[:-1])
        gains = [(fitted[k] - refolded[k], k, folded[k]) for k in np.flatnonzero(heard[:-1])]
        if heard[-1]:
            hinge = joints[-2] if p > 1 else self.model.pivot_of(joints)
            _, ends = tip_circle(self.model, hinge, fit_slew(joints, self.model.base))
            # The circle and, last, the tip where it was fitted.
            loss = self._tag_losses(np.vstack([ends, joints[-1]])[:, None], ranges[-1:],
                                    sigma[-1:])[:, 0]
            away = np.linalg.norm(ends - joints[-1], axis=1) > self.ALTERNATIVE_DISTANCE
            others = tip_minima(loss[:-1], away)
            if others.size:
                gains.append((loss[-1] - loss[others[0]], p - 1, ends[others[0]]))
        starts = []
        for gain, k, position in sorted(gains, key=lambda g: -g[0])[:self.FOLD_STARTS]:
            if gain > self.FOLD_MARGIN:
                start = joints.copy()
                start[k] = position
                starts.append(start)
        return starts

    def _fit_cost(self, joints, ranges):
        """Return the judge's loss of the measured ranges at ``joints``; inf below ground."""
        if joints[:, 2].min() < self.lowest_joint or not np.all(np.isfinite(joints)):
            return np.inf
        return float(np.sum(self._tag_losses(joints, ranges, self._range_sigma(ranges))))

    def _beam(self, ranges):
        """Return each slew of the beam search with its best chain: slews (s,), psi (s, p + 1)."""
        sigma = self._range_sigma(ranges)
        slews = np.linspace(-np.pi, np.pi, self.SEARCH_SLEWS, endpoint=False)
        pitches, costs = grow_chains(self.model, Measurements.ranges_only(ranges), sigma,
                                     self.nlos, slews, self.lowest_joint, width=4,
                                     candidates=self.SEARCH_PITCHES)
        order = np.argsort(costs[:, 0])
        best = order[np.isfinite(costs[order, 0])]
        return np.c_[slews[best], pitches[best, 0]]

    def _cold_starts(self, ranges, beam=None):
        """Return the best postures (k, p, 3) of the chain's beam search (cold-search starts)."""
        psi = (self._beam(ranges) if beam is None else beam)[:self.SEARCH_STARTS]
        return list(self.model.forward_kinematics(psi[:, 0], psi[:, 1:]))

    def _chain_searched(self, measurements):
        """
        Return the chain's global search's posture for the frame's ranges, or None.

        CEPP's own weights follow a range metres short to the fold that explains it; the
        chain's search (``ChainMethod.solve``, cold) screens its starts under the judge's
        loss, which lets that range go. None when it stopped at its budget (forgotten: the
        next cold frame searches afresh).
        """
        try:
            return self._finish.solve(self._ranged(measurements), None, warm=False)[0]
        except SearchExhausted:
            self._finish.reset()
            return None

    def _screened_peaks(self, ranges, beam, kept):
        """
        Return the likelihood's other peaks that the beam's chains climb to (rivals).

        Every slew's best chain takes ``SCREEN_ROUNDS`` Levenberg–Marquardt steps on the
        ranges, all side by side (``ChainMethod.fit_links``); the fits further than
        ``ALTERNATIVE_DISTANCE`` from ``kept`` (postures (k, p, 3)) and from each other,
        likeliest first, at most ``SCREEN_PEAKS``. CEPP solves from a few starts only:
        these are for the integrity checks to weigh, as the chain's search gives its own.
        """
        if not len(beam):
            return []
        sigma = self._range_sigma(ranges)
        masks = np.ones((len(beam),) + ranges.shape, dtype=bool)
        postures, costs = self._finish.fit_links(beam, ranges, sigma, masks,
                                                 self.SCREEN_ROUNDS)
        found = list(kept)
        peaks = []
        for k in np.argsort(costs):
            if len(peaks) == self.SCREEN_PEAKS or not np.isfinite(costs[k]):
                break
            if all(np.abs(postures[k] - other).max() > self.ALTERNATIVE_DISTANCE
                   for other in found):
                found.append(postures[k])
                peaks.append(postures[k])
        return peaks
