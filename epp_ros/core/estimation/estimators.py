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

- ``epp1``, ``epp2``, ``cepp_paper``: the paper's NEDM estimators as published
  (``methods.epp``): in 3-D without and with the arm lengths, and in the boom's vertical
  plane;
- ``cepp`` (the default): our field CEPP (``methods.field_cepp``), the paper's with the
  plane fitted to each frame, NLOS links discounted, silent tags held and searches beyond
  the warm start, each an option of its own.
- ``chain``: least squares over the slew and the pitches (``methods.chain``), at the
  Cramér–Rao bound, robust to NLOS ranges; also fuses tag-tag ranges and angle sensors.
- the paper's baselines (``methods.baselines``): ``srls`` (each tag alone), ``sdp`` (the
  Biswas–Ye relaxation; needs the optional cvxpy) and ``tpsm`` (angle sensors only).
"""
from dataclasses import asdict, fields
import math
import numbers
import time
from typing import NamedTuple, Optional

from epp_ros.core.estimation.integrity import ERROR, Integrity, IntegrityLimits, OK, Thresholds
from epp_ros.core.estimation.learned_errors import LearnedErrors, told_noise
from epp_ros.core.estimation.methods.registry import make_method, method_options, METHODS
from epp_ros.core.estimation.noise_learning import frame_scale
from epp_ros.core.estimation.posture_method import FrameResult
from epp_ros.core.estimation.reacquisition import Reacquisition
from epp_ros.core.model.bounds import RangeBiasPrior
from epp_ros.core.model.measurements import Measurements, plausible_limits, Residuals, SensorNoise
from epp_ros.core.model.nlos import NlosMixture, OUTLIER_FRACTION
from epp_ros.core.model.noise import DEFAULT_NOISE, link_bias_stds, NoiseModel
from epp_ros.core.model.vectors import norms
from epp_ros.core.solvers.multilateration import cold_start_guess
import numpy as np

__all__ = ['PostureEstimator', 'ESTIMATOR_OPTIONS', 'accepted_options']


#: Options of the estimator itself, given to every method that accepts them: what it is
#: told about the noise (``NoiseModel``, which the integrity checks use for every method)
#: and the ground.
ESTIMATOR_OPTIONS = {**asdict(DEFAULT_NOISE), 'lowest_joint': -0.5}


def accepted_options(method):
    """Names of the keyword options ``PostureEstimator(model, method, ...)`` takes."""
    return set(ESTIMATOR_OPTIONS) | method_options(method)


NOISE_FIELDS = tuple(field.name for field in fields(NoiseModel))


def _anchor_indices(anchors, count):
    """Return ``anchors`` as sorted unique indices below ``count``; ValueError otherwise."""
    try:
        indices = sorted({int(j) for j in anchors})
    except (TypeError, ValueError) as exc:
        raise ValueError(f'moving_anchors: must be anchor indices, got {anchors!r}') from exc
    if any(j < 0 or j >= count for j in indices):
        raise ValueError(f'moving_anchors: must be in [0, {count}), got {list(anchors)!r}')
    return tuple(indices)


def _told(options):
    """Return the estimator options with their defaults, checked (ValueError naming the option)."""
    noise = NoiseModel(**{name: options[name] for name in NOISE_FIELDS if name in options})
    lowest = options.get('lowest_joint', ESTIMATOR_OPTIONS['lowest_joint'])
    if isinstance(lowest, bool) or not isinstance(lowest, numbers.Real) \
            or not np.isfinite(lowest):
        raise ValueError(f'lowest_joint: must be a finite number, got {lowest!r}')
    return {**noise.told(), 'lowest_joint': float(lowest)}


def _integrity(model, told, limits, thresholds, moving=()):
    """Return the :class:`Integrity` of the noise the estimator is told (``moving``: anchors)."""
    noise = SensorNoise(float(told['sigma']), float(told['tag_sigma']),
                        float(told['pitch_sigma']), float(told['slew_sigma']))
    nlos = NlosMixture(float(told['nlos_fraction']), float(told['nlos_gamma'])).judged(
        told.get('outlier_fraction', OUTLIER_FRACTION))
    links = (model.n_sections, model.n_anchors)
    bias = RangeBiasPrior(link_bias_stds(told['link_bias_std'], links),
                          float(told['common_bias_std']),
                          float(told['bias_slope_std']), float(told['anchor_std']), moving)
    return Integrity(model, noise, nlos, told['eta'], told['lowest_joint'], limits, thresholds,
                     bias)


class _Accepted(NamedTuple):
    """The last posture published: what the next frames' jumps and rivals are judged by."""

    joints: np.ndarray          #: (p, 3), metres
    stamp: float                #: its frame's time, seconds
    joint_std: np.ndarray       #: (p,) m: its verdict's ``reach_std``
    turn_std: np.ndarray        #: (p,) rad: each section's direction, ``reach_turn_std``


class _Lesson(NamedTuple):
    """What a judged frame teaches the noise and bias learners, kept until :meth:`settle`."""

    timed: np.ndarray           #: (p, 3) m: each joint when its tag ranged
    measurements: Measurements  #: the frame, bias taken off
    dof: int                    #: parameters its fit spent
    status: str                 #: its verdict's
    kept: np.ndarray            #: (p, m) bool: links measured and judged line-of-sight
    rows: Optional[np.ndarray]  #: the judge's Jacobian rows of those links, if it has them
    angles: tuple               #: (slew, pitches (p,)) rad, as judged


class PostureEstimator:
    """
    Frame-by-frame boom posture from UWB ranges (and, for some methods, angle sensors).

    Every estimate is judged by :class:`~epp_ros.core.estimation.integrity.Integrity` before it is
    called valid or kept as the next frame's warm start: a frame whose residuals the noise
    cannot explain, whose posture it does not determine, or which puts the boom where it
    cannot be, is reported invalid with its reason. When the warm start looks lost the
    frame is also solved from scratch, and that fit taken if it passes.

    Parameters
    ----------
    model : BoomModel
    method : str
        One of ``METHODS``: ``"cepp"`` (our field CEPP), ``"chain"``, ``"track"``, the
        paper's ``"epp1"``, ``"epp2"``, ``"cepp_paper"``, or a baseline, ``"srls"``,
        ``"sdp"``, ``"tpsm"``.
    integrity : IntegrityLimits
        How the consistency and observability checks decide.
    thresholds : Thresholds
        WARN and ERROR levels; a frame at ERROR is not valid.
    reset_after_failures : int
        Frames in a row that could not be solved or did not fit, after which the warm
        start is dropped.
    learn_noise : bool
        Learn the range noise (``sigma``, ``eta``, ``nlos_fraction``, ``nlos_gamma``) from
        the residuals while running (``core.noise_learning``), starting from the told
        values, and the range bias common to all links (``core.bias_learning``), starting
        from none; the solver and the integrity checks then use what was learned, from the
        frame after (a frame is learned from once answered: :meth:`settle`). False: the
        told values stay (benchmarks that tell the truth).
    learn_anchors : bool
        Also learn how far each of ``moving_anchors`` stands from where configured, with
        the common bias (``learn_noise``). False (the default): the shifts are only counted
        in the predicted joint standard deviations (``anchor_std``, then what the frames
        show of them; ``core.estimation.bias_learning``). Learning them helps where the
        links are unbiased (calibrated) and the outriggers were not surveyed; on
        uncalibrated real links the shifts take the links' own biases for theirs.
    moving_anchors : sequence of int
        The anchors off the truck body (outriggers') that may stand elsewhere than
        configured, by ``anchor_std`` per axis: what a set-up may have moved adds to the
        predicted joint standard deviations (a shifted anchor moves the fit without showing
        in its residuals). Empty (the default): every anchor is where configured.
    **options
        What the estimator is told, for every method (``ESTIMATOR_OPTIONS``): ``sigma``
        (tag-anchor range standard deviation, 0.1 m), ``eta`` (multiplicative range
        noise, 0), ``tag_sigma`` (tag-tag ranges; ``sigma``), ``pitch_sigma`` and
        ``slew_sigma`` (angle sensors, 0.5 deg), ``nlos_fraction`` (0.1) and ``nlos_gamma``
        (1 m), ``lowest_joint`` (-0.5 m), ``link_bias_std`` (0.1 m; or one per link,
        shape (p, m), as a calibration leaves each link's offset known), ``common_bias_std``
        (0.25 m) and ``bias_slope_std`` (0.01 m/m): what is not known of the ranges' biases
        once the model's offsets are taken off, each link's own and the part common to
        all, an offset and a growth with range (uncalibrated DW1000-class links: see
        ``core.bounds.RangeBiasPrior``), and ``anchor_std`` (0.1 m per axis, for the
        ``moving_anchors``; calibration writes what it leaves unknown); they add to the
        predicted joint standard deviations the thresholds judge, and with ``learn_noise``
        the common part is learned and taken off the ranges (``core.bias_learning``). And
        the method's own:
        ``prior_weight`` (weight of tag-tag distances from the previous pose, default 0;
        the paper uses 1),
        ``anchor_weight`` (inf: anchor-anchor distances fixed, the default; a number:
        weighted), ``tol``, ``max_iter``, ``irls_iterations`` (NLOS reweighting; the paper:
        0); both CEPPs also ``predict_slew`` (the plane fitted to the frame; the paper's:
        false, the previous pose's plane), ``slew_iterations`` (re-solves after refining
        the slew, default 0), ``slew_tol``, ``clip_weight``; the field ``cepp`` has
        ``predict_slew`` and ``irls_iterations`` (2) on, and ``noise_weights`` (links
        weighted by the noise model), ``silent_weight`` (a silent tag keeps the previous
        bends), ``cold_search`` and ``fold_search`` (searches beyond the warm start),
        ``polish`` (the answer finished at the likelihood's peak near it), each on by
        default and each off on its own; chain:
        ``tol``, ``max_iter``, ``slew_starts``, ``screen_iterations``; track: the chain's,
        ``process_noise`` (starting acceleration spectral density, rad^2/s^3),
        ``adapt_process_noise``, ``max_rate``, ``max_hypotheses``; sdp: ``solver``.

    Attributes
    ----------
    last_diagnostics : FrameResult
        Of the last :meth:`update` (None before the first), readable as a mapping:
        ``status`` (``"ok"``, ``"insufficient_data"``,
        ``"solver_failed"``, or the integrity's ``"inconsistent"``, ``"ambiguous"``,
        ``"unobservable"``, ``"implausible"``), ``valid`` (positions come from this frame
        and may be published), ``level`` (0 OK, 1 WARN, 2 ERROR) and ``message``,
        ``method``, ``cold_start``, ``reacquired`` (a fresh solve replaced the warm one),
        ``arm_length_error`` (p,) and ``section_lengths`` (p,) in metres,
        ``range_residual_rms`` (m), ``missing_links`` (including ``implausible_links``,
        those dropped as longer than the geometry allows), ``iterations``, ``solve_time``
        (s), the integrity's statistics (``chi_square``, ``chi_square_limit``,
        ``chi_square_dof``, ``variance_factor``: max(1, chi-square / dof), by whose root
        the predicted stds are widened,
        ``nlos_links`` and ``outlier_links`` (p, m), ``predicted_rmse`` (m), ``joint_std`` (p,),
        ``ambiguous_joints``, ``rival_margin``: nats by which the likeliest other position
        of a joint is less likely than the estimate's), the method's ``estimate`` (p, 3)
        whether valid or not, ``noise`` (the range noise the frame was judged with,
        :class:`RangeNoiseEstimate`), and solver details (``converged``, ...; track:
        ``rates`` (p + 1,), ``hypotheses``, ``manoeuvre``).

    """

    def __init__(self, model, method='cepp', *, integrity=IntegrityLimits(),
                 thresholds=Thresholds(), reset_after_failures=10, learn_noise=True,
                 learn_anchors=False, moving_anchors=(), **options):
        if method not in METHODS:
            raise ValueError(f'method must be one of {sorted(METHODS)}, got {method!r}')
        self.model = model
        self.moving_anchors = _anchor_indices(moving_anchors, model.n_anchors)
        self.method = method
        self._settings = {}
        self._learned = None            # LearnedErrors, with learn_noise
        self._lesson = None             # _Lesson: the last frame's, not yet learned
        self._reacquisition = None
        self.last_diagnostics = None
        self._configure(integrity=integrity, thresholds=thresholds,
                        reset_after_failures=reset_after_failures, learn_noise=learn_noise,
                        learn_anchors=learn_anchors, options=options)
        self._limits = plausible_limits(model)
        self._previous = None           # _Accepted: the last valid posture
        self._warm = None               # the last estimate that fitted its frame
        self._provisional = False       # _warm is a refused frame's fit (after a drop)
        self._stamp = None

    def reconfigure(self, *, integrity=None, thresholds=None, reset_after_failures=None,
                    learn_noise=None, learn_anchors=None, **options):
        """
        Change settings from the next frame on, keeping the warm start.

        Takes the constructor's keywords; those not given keep their values. Raises
        ValueError, leaving the estimator as it was, when the new settings are invalid.
        """
        changes = {'integrity': integrity, 'thresholds': thresholds,
                   'reset_after_failures': reset_after_failures, 'learn_noise': learn_noise,
                   'learn_anchors': learn_anchors}
        settings = {**self._settings, **{k: v for k, v in changes.items() if v is not None}}
        settings['options'] = {**self._settings['options'], **options}
        self.settle()                   # the frames before were learned from as they were
        self._configure(**settings)

    def _configure(self, integrity, thresholds, reset_after_failures, learn_noise,
                   learn_anchors, options):
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
        for name, value in (('learn_noise', learn_noise), ('learn_anchors', learn_anchors)):
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f'{name}: must be true or false, got {value!r}')
        told = _told(options)
        checks = _integrity(self.model, told, integrity, thresholds, self.moving_anchors)
        solver = make_method(self.model, method, {**options, **told})
        self._checks, self._solver = checks, solver
        if self._reacquisition is None:
            self._reacquisition = Reacquisition()
        self._reacquisition.reset_after_failures = int(reset_after_failures)
        keep = (learn_noise and self._learned is not None
                and self._learned.learned_from(told, learn_anchors))
        if not keep:            # what was learned from other told values starts over
            self._learned = LearnedErrors(self.model, told, self.moving_anchors,
                                          learn_anchors) if learn_noise else None
        self._told = told
        self._settings = {'integrity': integrity, 'thresholds': thresholds,
                          'reset_after_failures': reset_after_failures,
                          'learn_noise': bool(learn_noise),
                          'learn_anchors': bool(learn_anchors), 'options': dict(options)}
        if keep:
            self._use_noise(self._learned.noise)
        self._share_bias()

    @property
    def reset_after_failures(self):
        """Return the failures in a row after which the warm start is dropped."""
        return self._reacquisition.reset_after_failures

    def settle(self):
        """
        Learn what the last frame teaches now: its residuals' noise and bias.

        They change only the frames after it, so :meth:`update` hands its posture over
        first and leaves them (a tenth of a frame's time, and a learning round's several
        milliseconds every few frames) to the next :meth:`update`, to this call, or to
        whatever reads what is learned (:attr:`noise`, :attr:`range_bias`,
        :attr:`anchor_shifts`, :attr:`seen_anchor_shifts`, :attr:`integrity`), each of
        which calls it. A node calls it once the frame's posture is published, while it
        waits for the next. Every frame is estimated and judged as if each frame before it
        had been learned from at once.
        """
        lesson, self._lesson = self._lesson, None
        if lesson is not None:
            self._learn(lesson)
            self._learn_bias(lesson)

    @property
    def integrity(self):
        """Return the :class:`Integrity` that judges the next frame (the noise learned)."""
        self.settle()
        return self._checks

    @property
    def noise(self):
        """Return the range noise in use (:class:`RangeNoiseEstimate`): learned or told."""
        self.settle()
        return told_noise(self._told) if self._learned is None else self._learned.noise

    def _use_noise(self, estimate):
        """Give the solver and the integrity checks the range noise ``estimate``."""
        told = {**self._told, **estimate.as_options()}
        if self._settings['options'].get('tag_sigma') is None:
            told['tag_sigma'] = estimate.sigma          # tag-tag ranges are UWB ranges too
        self._checks = _integrity(self.model, told, self._settings['integrity'],
                                  self._settings['thresholds'], self.moving_anchors)
        self._share_bias()
        if hasattr(self._solver, 'tune'):
            self._solver.tune(**estimate.as_options())

    def _share_bias(self):
        """Tell the integrity checks what is still unknown of the learned common bias."""
        if self._learned is not None:
            self._checks.common_covariance = self._learned.bias_covariance()

    @property
    def range_bias(self):
        """Return the common range bias taken off (offset m, slope m/m at 20 m), or zeros."""
        self.settle()
        return np.zeros(2) if self._learned is None else self._learned.range_bias

    @property
    def anchor_shifts(self):
        """Return how far each of ``moving_anchors`` stands from where configured (n, 3), m."""
        self.settle()
        if self._learned is None:
            return np.zeros((len(self.moving_anchors), 3))
        return self._learned.anchor_shifts

    @property
    def seen_anchor_shifts(self):
        """
        Return how far the frames show each of ``moving_anchors`` to stand (n, 3), m.

        :attr:`anchor_shifts` when learned (``learn_anchors``); otherwise what the frames
        show while the shifts are only counted: taken off nothing, a cue to calibrate.
        """
        self.settle()
        if self._learned is None:
            return np.zeros((len(self.moving_anchors), 3))
        return self._learned.seen_shifts

    def _unbiased(self, measurements):
        """
        Return ``measurements`` with the learned bias taken off the ranges.

        An anchor's shift lengthens its ranges along the directions to the tags: those of
        the last posture that fitted its frame (none yet: the shifts wait).
        """
        if self._learned is None or not self._learned.biased:
            return measurements             # nothing learned yet: no directions to compute
        warm = None if self._provisional else self._warm
        return self._learned.unbiased(
            measurements, None if warm is None else self._checks.anchor_directions(warm))

    def _learn_bias(self, lesson):
        """
        Add a frame's line-of-sight residuals to the common bias learned.

        From frames published, and from those refused only as too uncertain: the prior on
        the bias alone can make the first frames so, and only frames can shrink it. Each
        tag is where it was when it ranged (``timed_joints``), for a method that knows. The
        fit's Jacobian over those links is the one its verdict judged it with, when it has one.
        """
        if lesson.status not in ('ok', 'unobservable'):
            return
        measurements, kept, timed = lesson.measurements, lesson.kept, lesson.timed
        sigma = self._checks.link_sigma(measurements)
        rows = lesson.rows
        if rows is None:        # a method not held to the chain: not in its judgement
            residuals = Residuals(self.model, Measurements.ranges_only(
                np.where(kept, measurements.ranges, np.nan)), SensorNoise(sigma))
            rows = residuals.rows(np.r_[lesson.angles[0], lesson.angles[1]])
        fitted = self.model.ranges(timed)[kept]
        scaled = (fitted - measurements.ranges[kept]) / sigma[kept]
        # Scaled by the noise now in use, which learning may have changed since the judgement.
        if self._learned.observe_bias(rows / sigma[kept][:, None], sigma[kept], scaled,
                                      fitted, np.flatnonzero(kept),
                                      self._checks.anchor_directions(timed)[kept]):
            self._share_bias()

    def reset(self, joints=None):
        """
        Forget the warm start: the next frame is solved from scratch, or from ``joints``.

        Parameters
        ----------
        joints : array_like, shape (p, 3), optional
            A posture to start the next frame from (metres), e.g. a parking pose or one
            from another source. It seeds the solver only: the checks of the next frame
            decide whether what follows from it is valid. The noise learned is kept.

        """
        self.settle()
        seed = None
        if joints is not None:
            seed = np.array(joints, dtype=float)
            if seed.shape != (self.model.n_sections, 3) or not np.all(np.isfinite(seed)):
                raise ValueError(f'joints: must be finite, of shape '
                                 f'({self.model.n_sections}, 3), got {np.shape(joints)}')
        self._previous, self._warm, self._provisional = None, seed, False
        self._reacquisition.succeeded()
        self._solver.reset(seed)

    @property
    def previous(self):
        """Return the last valid estimate (p, 3), or None."""
        return None if self._previous is None else self._previous.joints.copy()

    def _fallback(self):
        if self._previous is not None:
            return self._previous.joints.copy()
        # Nothing known yet: a straight horizontal boom along +x, flagged invalid.
        return self.model.forward_kinematics(0.0, np.zeros(self.model.n_sections))

    def update(self, ranges, *, tag_ranges=None, pitches=None, slew=None, stamp=None,
               range_stamps=None):
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
        range_stamps : array_like, shape (p,), optional
            When each tag's row of ``ranges`` was measured, seconds on the clock of
            ``stamp``; NaN: at ``stamp``. Methods without a motion model ignore it.

        Inputs a method does not use are listed in ``last_diagnostics["ignored_inputs"]``.

        Returns
        -------
        joints : ndarray, shape (p, 3)
            Base outward, tip last. Never NaN: a frame that is not valid returns the last
            valid estimate, and ``last_diagnostics["valid"]`` is False.

        """
        self.settle()                   # the last frame's lesson, if not learned yet
        start = time.perf_counter()
        stamp = self._frame_time(stamp)
        p, m = self.model.n_sections, self.model.n_anchors
        measurements, implausible = Measurements.clean(self.model, ranges, tag_ranges,
                                                       pitches, slew, self._limits, stamp,
                                                       range_stamps)
        measurements = self._unbiased(measurements)
        valid = np.isfinite(measurements.ranges)
        diagnostics = {'method': self.method, 'noise': self.noise,
                       'range_bias': self.range_bias,
                       'anchor_shifts': dict(zip(self.moving_anchors,
                                                 self.seen_anchor_shifts)),
                       'missing_links': int(p * m - valid.sum()),
                       'implausible_links': implausible,
                       'cold_start': self._warm is None or self._provisional,
                       'reacquired': False, 'iterations': 0,
                       'ignored_inputs': [name for name in measurements.present()
                                          if name not in self._solver.inputs]}
        if range_stamps is not None and 'range_stamps' not in self._solver.inputs:
            diagnostics['ignored_inputs'].append('range_stamps')
        if not self._solver.enough_information(measurements):
            return self._reject('insufficient_data', diagnostics, measurements, start)
        solved = self._solve(measurements, warm=self._warm is not None)
        if isinstance(solved, str):
            diagnostics['error'] = solved
            return self._reject('solver_failed', diagnostics, measurements, start)
        verdict = self._judge(solved, measurements, stamp)
        if self._provisional and not verdict.lost and not solved[1].get('searched'):
            # From a refused frame's fit: what it leads to stands only if a search finds it.
            solved = self._solve(measurements, warm=False)
            if isinstance(solved, str):
                diagnostics['error'] = solved
                return self._reject('solver_failed', diagnostics, measurements, start)
            verdict = self._judge(solved, measurements, stamp)
        elif self._warm is not None and not solved[1].get('searched'):
            solved, verdict = self._reconsider(solved, verdict, measurements, stamp,
                                               diagnostics)
        if self._learned is not None and not self._learned.settled:
            solved, verdict = self._bootstrap_noise(measurements, stamp, solved, verdict)
        joints, info = solved
        lesson = self._lesson_of(joints, info, measurements, verdict)
        diagnostics.update(info, noise=self.noise)       # as the frame was judged with
        if not verdict.lost and self._has_state:
            self._solver.accept(info)       # a motion model takes the fit as its state
        slew, pitches = verdict.angles
        diagnostics.update(verdict.values, estimate=joints, angles=(slew, pitches.copy()))
        diagnostics.update(level=verdict.level, message=verdict.message)
        if not verdict.lost:            # it fits the frame: the next frame's start
            self._warm, self._provisional = joints.copy(), False
        if not verdict.valid:
            returned = self._reject(verdict.status, diagnostics, measurements, start, joints)
        else:
            # A fold about as likely widens what later frames allow (Integrity.fold_spread).
            self._previous = _Accepted(joints.copy(), stamp, verdict.values['reach_std'],
                                       verdict.values['reach_turn_std'])
            self._reacquisition.succeeded()
            returned = self._finish(joints, 'ok', diagnostics, measurements, start)
        self._lesson = lesson           # learned after the posture is handed over: settle()
        return returned

    def _excess(self, joints, measurements):
        """Return measured minus fitted tag-anchor ranges and the fitted ones, (n,) each."""
        fitted = self.model.ranges(joints)
        measured = np.isfinite(measurements.ranges)
        return measurements.ranges[measured] - fitted[measured], fitted[measured]

    def _dof(self, info=None):
        """
        Return the parameters the frame's fit spent: the chain's angles, or each joint's own.

        Those a joint is free in (``free_per_joint``: 3, or 2 with its arm length held). A
        motion model says how many its prediction did not supply (``fitted_dof``).
        """
        if info is not None and 'fitted_dof' in info:
            return info['fitted_dof']
        p = self.model.n_sections
        if getattr(self._solver, 'holds_chain', True):
            return p + 1
        return getattr(self._solver, 'free_per_joint', 3) * p

    def _bootstrap_noise(self, measurements, stamp, solved, verdict, attempts=3):
        """
        Before the noise is learned, take the frame's own scale when far above the told one.

        A told sigma ten times too small makes every link look blocked, which can send a
        cold start to a wrong fit: the frame is solved again with its own scale, at most
        ``attempts`` times. A smaller scale waits for the window: trusting one frame's
        would make the estimator claim an accuracy it does not have. A fit a search made
        is solved again by a search: a warm start is what it replaced.
        """
        threshold = 2.0
        for _ in range(attempts):
            excess, fitted = self._excess(solved[1].get('timed_joints', solved[0]),
                                          measurements)
            factor = frame_scale(excess, self._learned.noise.link_sigma(fitted),
                                 self._dof(solved[1]), too_short_only=False)
            if not np.isfinite(factor) or factor <= threshold:   # one frame never shrinks it
                break
            threshold = 1.25                # once far off, settle it closely
            self._learned.rescale(factor)
            self._use_noise(self._learned.noise)
            again = self._solve(measurements, warm=self._warm is not None
                                and not solved[1].get('searched'))
            if isinstance(again, str):
                break
            solved, verdict = again, self._judge(again, measurements, stamp)
        return solved, verdict

    def _lesson_of(self, joints, info, measurements, verdict):
        """Return what a judged frame teaches (:class:`_Lesson`), or None (nothing learned)."""
        if self._learned is None:
            return None
        kept = np.isfinite(measurements.ranges)
        set_aside = self._set_aside(verdict)
        if set_aside is not None:
            kept &= ~set_aside
        # Copies: what the caller is handed may be changed before the lesson is learned.
        slew, pitches = verdict.angles
        return _Lesson(np.array(info.get('timed_joints', joints), dtype=float), measurements,
                       self._dof(info), verdict.status, kept,
                       None if verdict.los_rows is None else verdict.los_rows.copy(),
                       (slew, np.array(pitches, dtype=float)))

    def _learn(self, lesson):
        """Add the frame's residuals to the noise learned, unless its fit is impossible."""
        if lesson.status == 'implausible':
            return
        excess, fitted = self._excess(lesson.timed, lesson.measurements)
        if self._learned.observe_noise(excess, fitted, lesson.dof):
            self._use_noise(self._learned.noise)

    def _frame_time(self, stamp):
        """Return the frame's time, seconds: the stamp, or one frame period after the last."""
        if stamp is None:
            previous = -self._checks.limits.frame_period if self._stamp is None \
                else self._stamp
            stamp = previous + self._checks.limits.frame_period
        self._stamp = float(stamp)
        return self._stamp

    def _judge(self, solved, measurements, stamp):
        joints, info = solved
        known = {'alternatives': info.get('alternatives', ()),
                 'chain': getattr(self._solver, 'holds_chain', True),
                 'timed_joints': info.get('timed_joints'), 'rivals': info.get('rivals', ()),
                 'fitted_dof': self._dof(info)}
        if self._previous is None:
            return self._checks.judge(joints, measurements, **known)
        last = self._previous
        return self._checks.judge(joints, measurements, last.joints,
                                  max(stamp - last.stamp, 0.0), last.joint_std,
                                  reference_turn_std=last.turn_std, **known)

    def _reconsider(self, solved, verdict, measurements, stamp, diagnostics):
        """
        Solve a warm-started frame from scratch too, when its fit is lost, outweighed or doubted.

        Not when the method searched from scratch for this frame already. Returns the
        (joints, info) kept and its verdict; ``diagnostics["reacquired"]`` says whether
        the fresh fit won. Outweighed: a joint's rival position is likelier than the fit's
        (``Verdict.outweighed``), for a method with a state of its own, which gets no
        second opinion: at a site with a third of its ranges outliers the tracker held a
        wrong fold 4-10 nats less likely than the other, every frame refused. (Not for the
        others: their second opinions weigh such folds, and where a persistently blocked
        tip made its flipped fold the likelier, this search published it 16 m off.)
        Doubted (:meth:`_suspicious`): a second opinion, or for a method with a state a
        search beside it (:meth:`_searched_beside`); else, outweighed: :meth:`_likelier`.
        """
        if not verdict.outweighed:
            self._reacquisition.outweighed_by(None)         # the run of such frames ends
        if verdict.lost:
            if self._reacquisition.due_for_search():
                return self._searched_instead(solved, verdict, measurements, stamp,
                                              diagnostics)
            return solved, verdict
        if self._has_state:     # no second opinion: one would replace what many frames built
            if verdict.outweighed and self._reacquisition.due_for_rival_search():
                return self._searched_instead(solved, verdict, measurements, stamp,
                                              diagnostics)
            if self._suspicious(verdict, measurements, stamp):
                return self._searched_beside(solved, verdict, measurements, stamp,
                                             diagnostics)
            return solved, verdict
        if self._suspicious(verdict, measurements, stamp):
            solved, verdict, diagnostics['reacquired'] = self._second_opinion(
                solved, measurements, stamp, verdict)
        elif verdict.outweighed:
            solved, verdict, diagnostics['reacquired'] = self._likelier(
                solved, verdict, measurements, stamp)
        return solved, verdict

    def _likelier(self, solved, verdict, measurements, stamp):
        """
        Solve the frame from where its verdict puts a joint likelier; follow it once proven.

        A warm fit on a joint's wrong fold, refused as ambiguous, is still the next frame's
        start: on a four-anchor pump on the joystick the chain's warm fit followed the
        boom for a second with its other joints sliding, until the fold the judge weighs
        (the joint reflected between its neighbours) was no longer near the truth, and
        frames were published 5-6 m off at a predicted RMSE of 1 m. Solved from the
        likelier position, those frames found the truth. The fit so solved is taken (the
        likelier of the two, the other its alternative) once the evidence for it, summed
        over the frames in a row it outweighs (``Reacquisition.outweighed_by``), reaches
        the ambiguity odds; each frame's counts only the links neither fit sets aside:
        where a tip's ranges were blocked for seconds, its flipped fold was 9 nats likelier
        by the mixture's prior of blockage and 2.5 by the links both called clear.
        Returns (joints, info), verdict and whether the new fit won.
        """
        fresh = self._solve(measurements, warm=True, prior=verdict.likelier)
        if isinstance(fresh, str):
            return solved, verdict, False
        clear = np.isfinite(measurements.ranges)        # by both fits' lights
        for judged in (verdict, self._judge(fresh, measurements, stamp)):
            set_aside = self._set_aside(judged)
            if set_aside is not None:
                clear &= ~set_aside
        costs = self._checks.posture_cost(np.array([solved[0], fresh[0]]), measurements,
                                          clear)
        evidence = self._reacquisition.outweighed_by(float(costs[0] - costs[1]))
        if evidence < math.log(self._checks.limits.ambiguity_odds):
            return solved, verdict, False
        self._reacquisition.outweighed_by(None)             # followed: a run starts over
        best, _, verdict = self._weighed(solved, fresh, measurements, stamp)
        return best, verdict, best is fresh

    def _searched_instead(self, solved, verdict, measurements, stamp, diagnostics):
        """
        Return a search's fit and verdict where it passes, else ``solved`` and ``verdict``.

        ``diagnostics["reacquired"]`` is set when the search's fit is returned. The fit
        replaced stays the search's alternative unless the boom cannot be there: residuals
        the noise does not explain do not make it less likely, and at a site with a third
        of its ranges outliers, before their share was learned, a search replaced the
        truth's fit (called inconsistent) with a posture 10 nats less likely, published
        with two joints 12 m off at a predicted RMSE of 1.4 m.
        """
        fresh = self._solve(measurements, warm=False)
        if isinstance(fresh, str):
            return solved, verdict
        if verdict.status != 'implausible':
            _add_alternatives(fresh, [solved[0]])
        fresh_verdict = self._judge(fresh, measurements, stamp)
        if not fresh_verdict.valid:
            return solved, verdict
        diagnostics['reacquired'] = True
        return fresh, fresh_verdict

    def _searched_beside(self, solved, verdict, measurements, stamp, diagnostics):
        """
        Search beside a doubted fit of a method with a state; take the search's if proven.

        The search's fit replaces the state only where the frame makes it likelier by the
        ambiguity odds (a fit the motion model shaped is a little less likely on its frame
        alone than the frame's own best, and a search per doubt would replace what many
        frames built); else it stays the fit's alternative, and the frame is ambiguous
        where it is about as likely and elsewhere. On seven anchors, two tags silent for
        8 s, the tracker's fit drifted 15 m and, called four of each tag's seven links
        blocked, was published at a predicted RMSE of 1-1.8 m, where a search found one 32
        nats likelier. Returns (joints, info) and its verdict.
        """
        self._reacquisition.searched(stamp)
        fresh = self._solve(measurements, warm=False)
        if isinstance(fresh, str):
            return solved, verdict
        best, _, verdict = self._weighed(solved, fresh, measurements, stamp,
                                         math.log(self._checks.limits.ambiguity_odds))
        diagnostics['reacquired'] = best is fresh
        return best, verdict

    @property
    def _has_state(self):
        """Whether the method has a state of its own (a motion model's), kept by ``accept``."""
        return hasattr(self._solver, 'accept')

    def _set_aside(self, verdict):
        """Return the links the fit sets aside, blocked or outliers, (p, m) bool, or None."""
        blocked = verdict.values.get('nlos_links')
        outlying = verdict.values.get('outlier_links')
        if blocked is None or outlying is None:
            return blocked
        return blocked | outlying

    def _suspicious(self, verdict, measurements, stamp):
        """Judge whether a fit sets too many of a tag's links aside (``Reacquisition``)."""
        set_aside = self._set_aside(verdict)
        return set_aside is not None and self._reacquisition.suspicious(
            set_aside, measurements.ranges, stamp, verdict.values.get('outlier_links'))

    def _second_opinion(self, solved, measurements, stamp, verdict):
        """
        Solve the frame from scratch too, or from the rival in doubt; keep the fit it likes better.

        The other stays as an alternative: when it is about as likely and elsewhere, the
        frame is ambiguous. A doubt does not end on the rival followed alone: where the
        two fits leave the frame valid, a search is made too and weighed with them (at
        a site with a third of its ranges outliers, the likelier of a warm fit and a
        followed rival was published 7 m off, where a search found the truth's fold); nor
        on a search alone: the rival is weighed with it. The doubt lasts while a joint is
        ambiguous, and for the frame after a jump to another basin (the fit left further
        than ``ambiguity_distance``), weighed with the fit left: on a seven-anchor pump
        a jump to joint 4's other fold on a frame that preferred it by 11 nats was
        published on the next two, which preferred the basin left by 7, 6.5 m off at a
        predicted RMSE of 0.94 m. Returns (joints, info), verdict, and whether the other
        fit won.
        """
        rival = self._reacquisition.rival_start(stamp)
        fresh = self._solve(measurements, warm=rival is not None, prior=rival)
        if isinstance(fresh, str):
            self._reacquisition.searched(stamp)
            return solved, verdict, False
        best, other, verdict = self._weighed(solved, fresh, measurements, stamp)
        moved, searched = best is fresh, rival is None
        followed = self._reacquisition.rival
        if searched and followed is not None:
            # The rival followed is weighed with the search's fit, not forgotten for it: a
            # search can land in the warm fit's basin, and the two agreeing would end the
            # doubt with the truth last seen in the rival.
            kept = self._solve(measurements, warm=True, prior=followed)
            if not isinstance(kept, str):
                best, loser, verdict = self._weighed(best, kept, measurements, stamp)
                moved, other = moved or best is kept, kept if best is not kept else loser
        if not searched and verdict.valid:
            searched, found = True, self._solve(measurements, warm=False)
            if not isinstance(found, str):
                best, loser, verdict = self._weighed(best, found, measurements, stamp)
                if best is found:       # else the rival stays the one followed
                    moved, other = True, loser
        # In doubt while the other fit makes a joint ambiguous, whatever else refused the
        # frame: a likelier one beyond the reach of a drifted reference is followed so.
        # And on the frame after a jump to another basin: one frame's word is not enough.
        jumped = moved and np.max(norms(best[0] - other[0])) > \
            self._checks.limits.ambiguity_distance
        ambiguous = bool(verdict.values.get('ambiguous_joints')) or jumped
        if searched:
            self._reacquisition.searched(stamp, ambiguous, other[0])
        else:
            self._reacquisition.followed(ambiguous, other[0])
        return best, verdict, moved

    def _weighed(self, solved, fresh, measurements, stamp, margin=0.0):
        """
        Return the likelier of two fits of a frame, the other, and the likelier's verdict.

        ``fresh`` wins only where more than ``margin`` nats likelier. The other joins the
        likelier's alternatives, with its own. Not to a posture the boom cannot be in
        (beyond its reach since the last one).
        """
        costs = self._checks.posture_cost(np.array([solved[0], fresh[0]]), measurements)
        moved = bool(costs[0] - costs[1] > margin) and \
            self._judge(fresh, measurements, stamp).status != 'implausible'
        best, other = (fresh, solved) if moved else (solved, fresh)
        _add_alternatives(best, [other[0], *other[1].get('alternatives', [])])
        return best, other, self._judge(best, measurements, stamp)

    def _solve(self, measurements, warm, prior=None):
        """
        Return the method's (joints, info) from ``prior``, the warm start or a cold one.

        A string says why not.
        """
        if prior is None:
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

        Its place is taken by the refused fits, as provisional starts: a search per frame
        would make refused frames cost ten good ones (``Reacquisition`` spaces them).
        """
        diagnostics.setdefault('level', ERROR)
        diagnostics.setdefault('message', f'no estimate: {status}')
        if self._reacquisition.failed(status):
            self._previous, self._warm, self._provisional = None, None, True
            diagnostics['cold_restart'] = True
        if self._provisional and joints is not None:
            self._warm = joints.copy()
        estimate = self._fallback() if joints is None else joints
        self._finish(estimate, status, diagnostics, measurements, start)
        return self._fallback()

    def _finish(self, joints, status, diagnostics, measurements, start):
        lengths = self.model.section_lengths(joints)
        # Each tag where it was when it ranged, for a method that knows.
        residual = self.model.ranges(diagnostics.get('timed_joints', joints)) \
            - measurements.ranges
        valid = np.isfinite(residual)
        diagnostics.update(
            status=status, valid=status == 'ok', section_lengths=lengths,
            arm_length_error=np.abs(lengths - self.model.arm_lengths),
            range_residual_rms=float(np.sqrt(np.mean(residual[valid] ** 2))) if valid.any()
            else float('nan'),
            solve_time=time.perf_counter() - start)
        diagnostics.setdefault('level', OK)
        diagnostics.setdefault('message', 'tracking')
        self.last_diagnostics = FrameResult.from_values(diagnostics)
        return joints


def _add_alternatives(solved, postures):
    """Add ``postures`` (p, 3) each to a (joints, info) fit's alternatives for its judge."""
    info = solved[1]
    info['alternatives'] = [*info.get('alternatives', ()), *postures]
