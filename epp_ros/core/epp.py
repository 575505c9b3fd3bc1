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
"""
import numpy as np

from .edm import align_to_known, squared_distances
from .nedm import nearest_edm
from .plane import fit_plane_to_ranges, fit_slew, from_plane, project_ranges, slew_step, to_plane

__all__ = ['EPP1', 'EPP2', 'CEPP']


class _EDMMethod:
    """Shared machinery of the NEDM estimators: build G, H and the fixed set; solve; embed."""

    rank = 3
    fix_lengths = True
    prior = 'required'          # the tag-tag entries of G come from a prior posture
    inputs = ('ranges', 'tag_ranges')

    def __init__(self, model, prior_weight=0.0, anchor_weight=np.inf, tol=1e-6, max_iter=500):
        self.model = model
        self.prior_weight = float(prior_weight)
        self.anchor_weight = float(anchor_weight)
        self.tol = tol
        self.max_iter = max_iter
        base_anchor = model.base_anchor()
        self._base_anchor = base_anchor
        self._other_anchors = np.array([j for j in range(model.n_anchors) if j != base_anchor],
                                       dtype=int)

    def enough_information(self, measurements):
        """Whether the frame's tag-anchor links can determine the posture."""
        valid = np.isfinite(measurements.ranges)
        p = self.model.n_sections
        # Without lengths each tag stands alone: r + 1 ranges, or its mirror image fits too.
        per_tag, total = ((1, (self.rank - 1) * p) if self.fix_lengths
                          else (self.rank + 1, 3 * p))
        return valid.sum(axis=1).min() >= per_tag and valid.sum() >= total

    def reset(self):
        """Do nothing: the EDM methods keep no state of their own."""

    def _known_columns(self, ranges):
        """Ranges (p, k) from each tag to the known points: base first, then other anchors."""
        p = self.model.n_sections
        base_column = (ranges[:, self._base_anchor] if self._base_anchor is not None
                       else np.full(p, np.nan))
        return np.column_stack([base_column, ranges[:, self._other_anchors]])

    def _solve_edm(self, known, tag_squared, tag_weights, prior, tag_tag_ranges):
        """
        Solve the NEDM for tags given known points (k, d), squared ranges (p, k), prior.

        ``tag_tag_ranges`` (p, p), NaN where not measured, replace the prior's tag-tag
        entries of G with weight 1 (both directions measured: their mean square).
        """
        k, p = known.shape[0], prior.shape[0]
        n = k + p
        lengths_sq = self.model.arm_lengths ** 2
        initial = squared_distances(np.vstack([known, prior]))
        target = initial.copy()
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
        columns = self._known_columns(measurements.ranges)
        return self._solve_edm(known, columns ** 2, np.ones_like(columns), prior,
                               measurements.tag_ranges)


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
    """

    rank = 2
    holds_chain = True          # lengths and the vertical plane: the chain's bound applies
    #: Gauss-Newton steps when predicting the slew: from last frame's plane, three converge
    #: it far below what the ranges resolve.
    PREDICTION_STEPS = 3

    def __init__(self, model, clip_weight=0.1, predict_slew=True, slew_iterations=0,
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

    def _solve_in_plane(self, measurements, prior, slew):
        ranges = measurements.ranges
        base = self.model.base
        squared, clipped = project_ranges(ranges, self.model.anchors, base, slew)
        weights = np.where(clipped, self.clip_weight, 1.0)
        anchors_2d = to_plane(self.model.anchors, base, slew)
        known = np.vstack([[self.model.pivot_offset, base[2]], anchors_2d[self._other_anchors]])
        columns = self._known_columns(squared)
        column_weights = self._known_columns(weights)
        # Two tags in the plane are as far apart in it as in space.
        coords, info = self._solve_edm(known, columns, column_weights,
                                       to_plane(prior, base, slew), measurements.tag_ranges)
        return coords, info

    def solve(self, measurements, prior, warm=False):
        ranges = measurements.ranges
        slew = fit_slew(prior, self.model.base)
        if self.predict_slew:
            predicted, _ = fit_plane_to_ranges(
                to_plane(prior, self.model.base, slew), ranges, self.model.anchors,
                self.model.base, slew, (self.model.pivot_offset, self.model.base[2]),
                self.model.arm_lengths, self.PREDICTION_STEPS, self.slew_tol)
            slew = predicted if np.isfinite(predicted) else slew
        totals = {'iterations': 0, 'inner_iterations': 0}
        for attempt in range(self.slew_iterations + 1):
            coords, info = self._solve_in_plane(measurements, prior, slew)
            for key in totals:
                totals[key] += info[key]
            joints = from_plane(coords, self.model.base, slew)
            if attempt == self.slew_iterations:
                break
            step = slew_step(coords, ranges, self.model.anchors, self.model.base, slew)
            if abs(step) <= self.slew_tol:
                break
            slew, prior = slew + step, joints
        info.update(totals, slew=float(np.mod(slew + np.pi, 2 * np.pi) - np.pi))
        return joints, info
