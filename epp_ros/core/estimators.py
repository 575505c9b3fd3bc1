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
Posture estimators behind one interface, chosen by name.

``PostureEstimator(model, method)`` turns each frame of tag-anchor ranges (p, m) into joint
positions (p, 3), keeping the previous estimate as the warm start. Methods:

- ``epp1``: the paper's NEDM model in 3-D without the arm-length constraints.
- ``epp2``: the same with the arm lengths (base-joint 1 included) as equality constraints.
- ``cepp``: EPP2 in the boom's vertical plane (rank 2) after projecting the ranges.
- ``chain``: least squares over the slew and the pitches (``core.chain``), at the
  Cramér–Rao bound, robust to NLOS ranges; also fuses tag-tag ranges and angle sensors.
- the paper's baselines (``core.baselines``): ``srls`` (each tag alone), ``sdp`` (the
  Biswas–Ye relaxation; needs the optional cvxpy) and ``tpsm`` (angle sensors only).
"""
import inspect
import time

import numpy as np

from .baselines import SDPMethod, SRLSMethod, TPSMMethod
from .chain import ChainMethod
from .edm import align_to_known, squared_distances
from .integrity import ERROR, Integrity, IntegrityLimits, OK, Thresholds
from .measurements import Measurements, plausible_limits, SensorNoise
from .multilateration import intersect_spheres, srls
from .nedm import nearest_edm
from .nlos import NlosMixture
from .plane import fit_plane_to_ranges, fit_slew, from_plane, project_ranges, slew_step, to_plane

__all__ = ['PostureEstimator', 'METHODS', 'RANGE_METHODS', 'ESTIMATOR_OPTIONS',
           'accepted_options', 'cold_start_guess']


def cold_start_guess(model, ranges):
    """
    Joint positions from this frame's ranges alone, to seed a solver without a previous pose.

    Each tag is located by SR-LS from its anchor ranges; a tag with too few of them also uses
    its already located neighbours (or the base pivot) as spheres of radius the section
    length, repeated outward until nothing more can be located. Tags still unlocated take
    the position of the nearest located joint along the chain; they only seed the solver.

    Returns
    -------
    joints : ndarray, shape (p, 3), or None when no tag can be located.

    """
    p = model.n_sections
    lengths = model.arm_lengths
    joints = np.full((p, 3), np.nan)

    def neighbour_spheres(k):
        centres, radii = [], []
        # A pivot off the slew axis moves with the unknown slew: no sphere around it.
        inner = (model.base if model.pivot_offset == 0.0 else np.full(3, np.nan)) if k == 0 \
            else joints[k - 1]
        if np.isfinite(inner[0]):
            centres.append(inner)
            radii.append(lengths[k])
        if k + 1 < p and np.isfinite(joints[k + 1, 0]):
            centres.append(joints[k + 1])
            radii.append(lengths[k + 1])
        return centres, radii

    for use_neighbours in (False, True):
        progress = True
        while progress:
            progress = False
            for k in np.flatnonzero(~np.isfinite(joints[:, 0])):
                valid = np.isfinite(ranges[k])
                centres, radii = neighbour_spheres(k) if use_neighbours else ([], [])
                centres = np.vstack([model.anchors[valid]] + [np.reshape(centres, (-1, 3))])
                radii = np.concatenate([ranges[k, valid], radii])
                position = _locate(centres, radii, allow_three=use_neighbours)
                if position is not None:
                    joints[k] = position
                    progress = use_neighbours
    located = np.flatnonzero(np.isfinite(joints[:, 0]))
    if located.size == 0:
        return None
    for k in np.setdiff1d(np.arange(p), located):
        joints[k] = joints[located[np.argmin(np.abs(located - k))]]
    return joints


def _locate(centres, radii, allow_three):
    """Return a point at the given distances from distinct centres; the upper one if ambiguous."""
    _, first = np.unique(np.round(centres, 9), axis=0, return_index=True)
    first = np.sort(first)
    centres, radii = centres[first], radii[first]
    position = srls(centres, radii) if radii.size >= 4 else None
    if position is None and allow_three and radii.size >= 3:
        candidates = intersect_spheres(centres[:3], radii[:3])
        position = None if candidates is None else candidates[0]
    return position


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


METHODS = {'epp1': EPP1, 'epp2': EPP2, 'cepp': CEPP, 'chain': ChainMethod,
           'srls': SRLSMethod, 'sdp': SDPMethod, 'tpsm': TPSMMethod}

#: Methods that work from UWB ranges alone (what the estimator node receives).
RANGE_METHODS = [name for name, cls in METHODS.items() if 'ranges' in cls.inputs]


#: Options of the estimator itself, given to every method that accepts them: what it is
#: told about the noise (which the integrity checks use for every method) and the ground.
ESTIMATOR_OPTIONS = {'sigma': 0.1, 'eta': 0.0, 'tag_sigma': None, 'pitch_sigma': np.radians(0.5),
                     'slew_sigma': np.radians(0.5), 'nlos_fraction': 0.1, 'nlos_gamma': 1.0,
                     'lowest_joint': -0.5}


def accepted_options(method):
    """Names of the keyword options ``PostureEstimator(model, method, ...)`` takes."""
    return set(ESTIMATOR_OPTIONS) | _constructor_names(method)


def _constructor_names(method):
    """Names of the options the method's own constructor (and its bases') take."""
    names = set()
    for cls in METHODS[method].__mro__:
        if '__init__' in vars(cls):
            names |= {name for name, parameter in
                      inspect.signature(cls.__init__).parameters.items()
                      if parameter.kind in (parameter.KEYWORD_ONLY,
                                            parameter.POSITIONAL_OR_KEYWORD)
                      and name not in ('self', 'model')}
    return names


def _told(options):
    """Return the estimator options with their defaults, checked (ValueError naming the option)."""
    told = {name: options.get(name, default) for name, default in ESTIMATOR_OPTIONS.items()}
    for name, value in told.items():
        if value is not None and not (isinstance(value, (int, float, np.integer, np.floating))
                                      and np.isfinite(value)):
            raise ValueError(f'{name}: must be a finite number, got {value!r}')
    if told['eta'] < 0:
        raise ValueError(f'eta: must be >= 0, got {told["eta"]}')
    if told['tag_sigma'] is None:
        told['tag_sigma'] = told['sigma']
    return told


def _integrity(model, told, limits, thresholds):
    """Return the :class:`Integrity` of the noise the estimator is told."""
    noise = SensorNoise(float(told['sigma']), float(told['tag_sigma']),
                        float(told['pitch_sigma']), float(told['slew_sigma']))
    nlos = NlosMixture(float(told['nlos_fraction']), float(told['nlos_gamma']))
    return Integrity(model, noise, nlos, told['eta'], told['lowest_joint'], limits, thresholds)


class PostureEstimator:
    """
    Frame-by-frame boom posture from UWB ranges (and, for some methods, angle sensors).

    Every estimate is judged by :class:`~epp_ros.core.integrity.Integrity` before it is
    called valid or kept as the next frame's warm start: a frame whose residuals the noise
    cannot explain, whose posture it does not determine, or which puts the boom where it
    cannot be, is reported invalid with its reason. When the warm start looks lost the
    frame is also solved from scratch, and that fit taken if it passes.

    Parameters
    ----------
    model : BoomModel
    method : str
        One of ``METHODS``: ``"epp1"``, ``"epp2"``, ``"cepp"``, ``"chain"``, or a baseline,
        ``"srls"``, ``"sdp"``, ``"tpsm"``.
    integrity : IntegrityLimits
        How the consistency and observability checks decide.
    thresholds : Thresholds
        WARN and ERROR levels; a frame at ERROR is not valid.
    reset_after_failures : int
        Frames in a row that could not be solved or did not fit, after which the warm
        start is dropped.
    **options
        What the estimator is told, for every method (``ESTIMATOR_OPTIONS``): ``sigma``
        (tag-anchor range standard deviation, 0.1 m), ``eta`` (multiplicative range
        noise, 0), ``tag_sigma`` (tag-tag ranges; ``sigma``), ``pitch_sigma`` and
        ``slew_sigma`` (angle sensors, 0.5 deg), ``nlos_fraction`` (0.1) and ``nlos_gamma``
        (1 m), ``lowest_joint`` (-0.5 m). And the method's own: ``prior_weight`` (weight
        of tag-tag distances from the previous pose, default 0; the paper uses 1),
        ``anchor_weight`` (inf: anchor-anchor distances fixed, the default; a number:
        weighted), ``tol``, ``max_iter``; CEPP also ``predict_slew`` (default true; false:
        the paper's plane from the previous pose), ``slew_iterations`` (re-solves after
        refining the slew, default 0), ``slew_tol`` and ``clip_weight``; chain:
        ``tol``, ``max_iter``, ``slew_starts``, ``screen_iterations``; sdp: ``solver``.

    Attributes
    ----------
    last_diagnostics : dict
        Of the last :meth:`update`: ``status`` (``"ok"``, ``"insufficient_data"``,
        ``"solver_failed"``, or the integrity's ``"inconsistent"``, ``"ambiguous"``,
        ``"unobservable"``, ``"implausible"``), ``valid`` (positions come from this frame
        and may be published), ``level`` (0 OK, 1 WARN, 2 ERROR) and ``message``,
        ``method``, ``cold_start``, ``reacquired`` (a fresh solve replaced the warm one),
        ``arm_length_error`` (p,) and ``section_lengths`` (p,) in metres,
        ``range_residual_rms`` (m), ``missing_links`` (including ``implausible_links``,
        those dropped as longer than the geometry allows), ``iterations``, ``solve_time``
        (s), the integrity's statistics (``chi_square``, ``chi_square_limit``,
        ``nlos_links`` (p, m), ``predicted_rmse`` (m), ``joint_std`` (p,),
        ``ambiguous_joints``), the method's ``estimate`` (p, 3) whether valid or not, and
        solver details (``converged``, ...).

    """

    def __init__(self, model, method='cepp', *, integrity=IntegrityLimits(),
                 thresholds=Thresholds(), reset_after_failures=10, **options):
        if method not in METHODS:
            raise ValueError(f'method must be one of {sorted(METHODS)}, got {method!r}')
        self.model = model
        self.method = method
        self._settings = {}
        self._configure(integrity=integrity, thresholds=thresholds,
                        reset_after_failures=reset_after_failures, options=options)
        self._limits = plausible_limits(model)
        self._previous = None           # (joints, stamp, joint_std) last accepted
        self._warm = None               # the last estimate that fitted its frame
        self._stamp = None
        self._failures = 0
        self.last_diagnostics = {}

    def reconfigure(self, *, integrity=None, thresholds=None, reset_after_failures=None,
                    **options):
        """
        Change settings from the next frame on, keeping the warm start.

        Takes the constructor's keywords; those not given keep their values. Raises
        ValueError, leaving the estimator as it was, when the new settings are invalid.
        """
        changes = {'integrity': integrity, 'thresholds': thresholds,
                   'reset_after_failures': reset_after_failures}
        settings = {**self._settings, **{k: v for k, v in changes.items() if v is not None}}
        settings['options'] = {**self._settings['options'], **options}
        self._configure(**settings)

    def _configure(self, integrity, thresholds, reset_after_failures, options):
        """Validate the settings and build the method and the integrity checks from them."""
        method = self.method
        unknown = set(options) - accepted_options(method)
        if unknown:
            raise ValueError(f'method {method!r} takes no option {sorted(unknown)}; it takes '
                             f'{sorted(accepted_options(method))}')
        if isinstance(reset_after_failures, bool) or not isinstance(
                reset_after_failures, (int, np.integer)) or reset_after_failures < 1:
            raise ValueError(f'reset_after_failures: must be an integer >= 1, got '
                             f'{reset_after_failures!r}')
        told = _told(options)
        checks = _integrity(self.model, told, integrity, thresholds)
        own = _constructor_names(method)
        solver = METHODS[method](self.model, **{name: value for name, value
                                                in {**options, **told}.items() if name in own})
        self.integrity, self._solver = checks, solver
        self.reset_after_failures = int(reset_after_failures)
        self._settings = {'integrity': integrity, 'thresholds': thresholds,
                          'reset_after_failures': reset_after_failures,
                          'options': dict(options)}

    def reset(self):
        """Forget the warm start: the next frame is solved from scratch."""
        self._previous = self._warm = None
        self._failures = 0
        self._solver.reset()

    @property
    def previous(self):
        """Return the last valid estimate (p, 3), or None."""
        return None if self._previous is None else self._previous[0].copy()

    def _fallback(self):
        if self._previous is not None:
            return self._previous[0].copy()
        # Nothing known yet: a straight horizontal boom along +x, flagged invalid.
        return self.model.forward_kinematics(0.0, np.zeros(self.model.n_sections))

    def update(self, ranges, *, tag_ranges=None, pitches=None, slew=None, stamp=None):
        """
        Estimate the joint positions from one frame of measurements.

        Parameters
        ----------
        ranges : array_like, shape (p, m)
            Tag-anchor distances, metres; row k is the tag on joint k+1, column j anchor j;
            NaN, inf, negative or impossibly long entries count as missing.
        tag_ranges : array_like, shape (p, p), optional
            Tag-tag distances, metres, NaN where not measured.
        pitches : array_like, shape (p,), optional
            Inclinometer pitch of each section, radians, NaN where not measured.
        slew : float, optional
            Slew encoder angle, radians.
        stamp : float, optional
            The frame's time, seconds: how far the boom can have moved since the last
            accepted posture. Without it frames are ``integrity.frame_period`` apart.

        Inputs a method does not use are listed in ``last_diagnostics["ignored_inputs"]``.

        Returns
        -------
        joints : ndarray, shape (p, 3)
            Base outward, tip last. Never NaN: a frame that is not valid returns the last
            valid estimate, and ``last_diagnostics["valid"]`` is False.

        """
        start = time.perf_counter()
        stamp = self._frame_time(stamp)
        p, m = self.model.n_sections, self.model.n_anchors
        measurements, implausible = Measurements.clean(self.model, ranges, tag_ranges,
                                                       pitches, slew, self._limits)
        valid = np.isfinite(measurements.ranges)
        diagnostics = {'method': self.method, 'missing_links': int(p * m - valid.sum()),
                       'implausible_links': implausible, 'cold_start': self._warm is None,
                       'reacquired': False, 'iterations': 0,
                       'ignored_inputs': [name for name in measurements.present()
                                          if name not in self._solver.inputs]}
        if not self._solver.enough_information(measurements):
            return self._reject('insufficient_data', diagnostics, measurements, start)
        solved = self._solve(measurements, warm=self._warm is not None)
        if isinstance(solved, str):
            diagnostics['error'] = solved
            return self._reject('solver_failed', diagnostics, measurements, start)
        joints, info = solved
        verdict = self._judge(solved, measurements, stamp)
        # A fresh solve, unless the method searched from scratch for this frame already.
        if verdict.lost and self._warm is not None and not info.get('searched') \
                and self._due_for_search():
            fresh = self._solve(measurements, warm=False)
            if not isinstance(fresh, str):
                fresh_verdict = self._judge(fresh, measurements, stamp)
                if fresh_verdict.valid:
                    (joints, info), verdict = fresh, fresh_verdict
                    diagnostics['reacquired'] = True
        diagnostics.update(info)
        diagnostics.update(verdict.values, estimate=joints)
        diagnostics.update(level=verdict.level, message=verdict.message)
        if not verdict.lost:            # it fits the frame: the next frame's start
            self._warm = joints.copy()
        if not verdict.valid:
            return self._reject(verdict.status, diagnostics, measurements, start, joints)
        self._previous = (joints.copy(), stamp, verdict.values['joint_std'])
        self._failures = 0
        return self._finish(joints, 'ok', diagnostics, measurements, start)

    def _frame_time(self, stamp):
        """Return the frame's time, seconds: the stamp, or one frame period after the last."""
        if stamp is None:
            previous = -self.integrity.limits.frame_period if self._stamp is None \
                else self._stamp
            stamp = previous + self.integrity.limits.frame_period
        self._stamp = float(stamp)
        return self._stamp

    def _judge(self, solved, measurements, stamp):
        joints, info = solved
        known = {'alternatives': info.get('alternatives', ()),
                 'chain': getattr(self._solver, 'holds_chain', True)}
        if self._previous is None:
            return self.integrity.judge(joints, measurements, **known)
        reference, then, reference_std = self._previous
        return self.integrity.judge(joints, measurements, reference, max(stamp - then, 0.0),
                                    reference_std, **known)

    def _due_for_search(self):
        """
        Judge whether this rejected frame gets a fresh solve.

        The first few in a run do, then every tenth, so that a stream of garbage does not
        cost a search per frame.
        """
        failures = self._failures + 1
        return failures & (failures - 1) == 0 or failures % 10 == 0

    def _solve(self, measurements, warm):
        """Return the method's (joints, info) from the warm start or a cold one; why not if not."""
        prior = self._warm if warm else None
        if prior is None and self._solver.prior != 'unused':
            prior = cold_start_guess(self.model, measurements.ranges)
        if prior is None and self._solver.prior == 'required':
            return 'no tag could be located for a start'
        try:
            joints, info = self._solver.solve(measurements, prior, warm=warm)
        except (np.linalg.LinAlgError, RuntimeError) as exc:
            return str(exc)
        if not np.all(np.isfinite(joints)):
            return 'the solver returned non-finite positions'
        return joints, info

    def _reject(self, status, diagnostics, measurements, start, joints=None):
        """
        Report an invalid frame; the warm start is dropped after too many in a row.

        A frame that fitted but did not determine the posture (ambiguous, unobservable)
        does not count: its fit is a good start for the next frame.
        """
        if status not in ('ambiguous', 'unobservable'):
            self._failures += 1
        diagnostics.setdefault('level', ERROR)
        diagnostics.setdefault('message', f'no estimate: {status}')
        if self._failures >= self.reset_after_failures:
            self._previous = self._warm = None
            self._failures = 0
            diagnostics['cold_restart'] = True
        estimate = self._fallback() if joints is None else joints
        self._finish(estimate, status, diagnostics, measurements, start)
        return self._fallback()

    def _finish(self, joints, status, diagnostics, measurements, start):
        lengths = self.model.section_lengths(joints)
        residual = self.model.ranges(joints) - measurements.ranges
        valid = np.isfinite(residual)
        diagnostics.update(
            status=status, valid=status == 'ok', section_lengths=lengths,
            arm_length_error=np.abs(lengths - self.model.arm_lengths),
            range_residual_rms=float(np.sqrt(np.mean(residual[valid] ** 2))) if valid.any()
            else float('nan'),
            solve_time=time.perf_counter() - start)
        diagnostics.setdefault('level', OK)
        diagnostics.setdefault('message', 'tracking')
        self.last_diagnostics = diagnostics
        return joints
