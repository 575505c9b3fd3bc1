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
Calibration: anchor positions and device range offsets from a recording of a moving boom.

Two errors dominate real UWB installations: every module adds a constant to its ranges
(its antenna delay), and the outrigger anchors sit wherever the outriggers were set up.
:func:`calibrate` fits them, together with every frame's posture, to a recording of
tag-anchor ranges (and, optionally, tag-tag ranges) taken while the boom moves.

The problem is one least squares over every frame's p + 1 angles (slew and pitches), the
free anchors' positions and the offsets. Each frame's ranges depend on its own angles and
on the few shared parameters only, so the normal equations are block-arrow shaped: the
angles are eliminated frame by frame (a Schur complement, as in bundle adjustment), which
leaves a small dense system in the shared parameters (``core.block_arrow``'s
Levenberg–Marquardt), with the analytic Jacobian (``BoomModel.joint_jacobian``).

The first fit is under the chain estimator's NLOS mixture (``core.nlos``), by iteratively
reweighted least squares. A symmetric robust loss (Huber, soft-L1) would not do here: NLOS
excesses are one-sided, so a symmetric loss leaves part of their mean in every estimated
location parameter, and the range offsets are exactly location parameters. Then each
range is judged: its probability of being NLOS, from its own excess under the mixture and
from its link's other frames (``core.blockage``: blocked links stay blocked for seconds, so
a small excess amid a blocked stretch is suspect); the next fits weight each range by its
probability of being clear, and judge again. Judged ranges are set aside rather than fitted
through the model of their excess: each blocked range would pull the fit by sigma/gamma,
and the offsets gather those pulls and the undetected small excesses over the recording.
Frames in which a tag between others is not located (under three ranges) are left out of
the joint fit: the sections on either side of it have two solutions there.

The noise is the estimators' (sigma growing with the range, ``eta``); with ``learn_noise``
it is learned from the first joint fit's residuals (``core.noise_learning``) and the fit
repeated under it. A mixture far from the data's biases the offsets too: a 10 % blocked
prior on clean ranges inflates the errors' chi-square by about half over 60 s of
recording.

Each frame's angles start from chain, warm-started through the recording; after each joint
fit chain goes through it again with the calibrated model (and solves the worst frames from
scratch), and every frame keeps whichever fits it best: a fold taken wrongly with the
configured model, or after a silent tag, is not kept.

Gauges. The fixed anchors (``fixed_anchors``: on the truck body) define the truck frame
together with the boom's base and slew axis. Two changes of the parameters leave every
range the same, and are fixed by convention:

- a constant added to every tag offset and taken from every anchor offset: the tag-anchor
  ranges alone determine only the link offsets ``tag_offsets[k] + anchor_offsets[j]``.
  Anchor-anchor ranges (``anchor_ranges``) measure ``anchor_offsets[i] +
  anchor_offsets[j]``, tag-tag ranges ``tag_offsets[k] + tag_offsets[l]``: either fixes
  the split by data, and every offset is then determined on its own. Without them the
  split is fixed by ``sum(tag_offsets) == sum(anchor_offsets)``, the split nearest to zero
  (the likeliest when every device's offset is drawn alike).
- when every fixed anchor is on the slew axis (the turret's pivot alone), a rotation of
  the free anchors about the axis, with every frame's slew (no range sees it, anchor-anchor
  ranges neither): the first free anchor off the axis then keeps its starting bearing (it
  defines the truck's x direction): the configured one, or the survey's.

Anchor self-survey. With anchor-anchor ranges, :func:`core.survey.survey_anchors` first
locates the free anchors and fits the anchor offsets from them alone (the configured
positions resolving what they cannot see); that is the start of the joint fit, in which the
anchor-anchor ranges are residuals too (robust, under the same NLOS mixture), so that the
recording refines the survey and the survey pins what the boom's motion leaves loose.
"""
from dataclasses import dataclass, field, replace
import time

from epp_ros.core.calibration.blockage import BlockageChain
from epp_ros.core.calibration.correlation import fit_noise_correlation, NoiseCorrelation
from epp_ros.core.calibration.survey import (anchor_range_rounds, ANCHOR_TOLERANCE, AnchorPairs,
                                             fixed_indices, irls, OFFSET_TOLERANCE, survey_anchors)
from epp_ros.core.calibration.verdict import (common_offset_std, implausible, link_offset_std,
                                              misfit, poorly_determined, scaled_covariance,
                                              verdict)
from epp_ros.core.estimation.methods.chain import angles_from_joints, ChainMethod, SearchExhausted
from epp_ros.core.estimation.noise_learning import NoiseLearner, RangeNoiseEstimate
from epp_ros.core.model.boom import ANCHOR_SEPARATION
from epp_ros.core.model.measurements import Measurements, Residuals
from epp_ros.core.model.nlos import NlosMixture
from epp_ros.core.model.noise import DEFAULT_NOISE
from epp_ros.core.solvers.block_arrow import eliminate, least_squares, normal_equations
import numpy as np
from scipy.special import expit

__all__ = ['CalibrationResult', 'calibrate']

#: Robust cost per range (in units of sigma squared) above which, and above three times the
#: median frame's, a frame of the joint fit is solved again from scratch (a wrong fold).
LOST_FRAME_COST = 1.0

#: Frames of the subsample each starting hypothesis is fitted on.
SELECTION_FRAMES = 150

#: Most Levenberg–Marquardt iterations of a hypothesis's fit: enough to rank them (the
#: best one's fit goes on over the whole recording).
SELECTION_ITERATIONS = 30

#: Fraction of the ranges judged otherwise (their NLOS probability moved by more than a
#: half) below which the joint fit is not repeated for them.
JUDGED_OTHERWISE = 1e-3

#: Metres: the size of the links' own offsets the fit starts from when it learns it (the
#: pair term of real two-way-ranging links is 4-8 cm RMS) ...
LINK_STD_START = 0.05
#: ... and the least it learns: smaller ones hide in the noise of any recording.
LINK_STD_FLOOR = 0.01
#: Most rounds of learning it (each a fit from the last; it stops at a 5 % change).
LINK_ROUNDS = 6

#: Standard deviations within which a range judged blocked still counts as noise when the
#: residuals' correlation in time is fitted.
NOISE_REACH = 3.0

#: Metres: how far off a link offset the recording does not determine counts as.
UNKNOWN_OFFSET = 1.0

#: Robust cost (units of sigma squared) by which chain's angles must fit a frame better
#: than the joint fit's to replace them: a fold, not the difference between the fit's
#: weighting of the ranges and the mixture's.
RESTART_GAIN = 2.0


@dataclass
class CalibrationResult:
    """
    What :func:`calibrate` found, how well it is determined, and the verdict.

    Standard deviations come from the Jacobian at the solution: the inverse of the
    information of the shared parameters (the angles marginalised), scaled by the
    residual variance; zero for what the gauges fix.
    """

    #: ``"ok"``, ``"poorly_excited"``, ``"misfit"`` (the model does not fit a tag, an anchor
    #: or a link as it fits the others) or ``"not_converged"``
    status: str
    message: str                #: the verdict, with what is poorly determined and why
    model: object               #: the calibrated BoomModel
    anchors: np.ndarray         #: (m, 3) metres
    anchor_offsets: np.ndarray  #: (m,) metres
    tag_offsets: np.ndarray     #: (p,) metres
    #: (p, m) metres, tag + anchor + the link's own: what the ranges determine
    link_offsets: np.ndarray
    pair_offsets: np.ndarray    #: (p, m) metres, each link's own offset (zeros: none fitted)
    link_std: float             #: metres, the prior size of the links' own offsets, or learned
    #: frames, the residuals' integrated autocorrelation time: correlated frames weigh as
    #: fewer independent ones in every standard deviation
    correlation: float
    arm_lengths: np.ndarray     #: (p,) metres: fitted (``fit_arm_lengths``), or the model's
    arm_length_std: np.ndarray  #: (p,) metres (0: not fitted)
    anchor_std: np.ndarray      #: (m, 3) metres per axis (0 for fixed anchors)
    anchor_offset_std: np.ndarray   #: (m,) metres (depends on the gauge)
    tag_offset_std: np.ndarray  #: (p,) metres (depends on the gauge)
    link_offset_std: np.ndarray     #: (p, m) metres
    common_offset_std: float        #: metres, of the links' mean offset
    #: metres, RMS range residual of chain's fits with the model given (on the subsample
    #: the starts are chosen on, every ``N // SELECTION_FRAMES``-th frame)
    rms_before: float
    rms_after: float            #: metres, RMS range residual calibrated, every frame used
    residual_scale: float       #: residual standard deviation in units of ``sigma``
    condition: float            #: of the normalised information of the shared parameters
    poorly_determined: list = field(default_factory=list)  #: names of uncertain parameters
    gauge: str = ''             #: how the gauges were fixed
    converged: bool = False
    iterations: int = 0
    frames_used: np.ndarray = None  #: (N,) bool, the frames fitted
    postures: np.ndarray = None     #: (N, p + 1) radians, each frame's fit (NaN: unused)
    nlos: np.ndarray = None         #: (N, p, m) posterior NLOS probability of each link
    #: of (free anchors' xyz, tag offsets, anchor offsets, the links' own offsets)
    covariance: np.ndarray = None
    seconds: float = 0.0            #: computation time
    #: the anchor self-survey that started the fit (``core.survey.SurveyResult``), None
    #: without anchor-anchor ranges
    survey: object = None
    #: metres, RMS of the anchor-anchor ranges' residuals calibrated (NaN without them)
    anchor_rms_after: float = float('nan')
    #: the tag-anchor range noise fitted under (``core.noise_learning.RangeNoiseEstimate``):
    #: as given, or learned (``learn_noise``)
    range_noise: object = None
    #: how long a blocked link stays blocked (seconds; frame periods without stamps), as
    #: given or learned; 0: every frame judged on its own
    nlos_duration: float = 0.0

    @property
    def link_bias_stds(self):
        """
        Return what the calibration leaves unknown of each link's offset (p, m), metres.

        The estimator's ``link_bias_std`` per link (``epp_calibrate`` writes it as
        ``link_offset_std``). A link offset the recording does not determine counts as
        unknown to :data:`UNKNOWN_OFFSET`.
        """
        return np.where(np.isfinite(self.link_offset_std),
                        np.minimum(self.link_offset_std, UNKNOWN_OFFSET), UNKNOWN_OFFSET)

    @property
    def bias_std(self):
        """
        Return what the calibration leaves unknown of the ranges' biases, metres.

        (each link's own, RMS over the links of :attr:`link_bias_stds`; the part common
        to all): the estimator's ``link_bias_std`` and ``common_bias_std`` for the
        calibrated model when told one number for every link.
        """
        return (float(np.sqrt(np.mean(self.link_bias_stds ** 2))),
                min(self.common_offset_std, UNKNOWN_OFFSET))

    @property
    def left_unknown(self):
        """
        Return the estimator's settings for the calibrated model: what it leaves unknown, m.

        ``link_bias_std`` and ``common_bias_std`` (:attr:`bias_std`), and ``anchor_std``:
        the largest standard deviation per axis of an anchor it located (0 when every
        anchor was held; one it does not determine counts as :data:`UNKNOWN_OFFSET`).
        ``epp_calibrate`` writes them to the pump.yaml (``CALIBRATED_SETTINGS``).
        """
        link_bias, common_bias = self.bias_std
        std = np.where(np.isfinite(self.anchor_std), self.anchor_std, UNKNOWN_OFFSET)
        return {'link_bias_std': link_bias, 'common_bias_std': common_bias,
                'anchor_std': float(min(np.max(std, initial=0.0), UNKNOWN_OFFSET))}

    @property
    def estimator_options(self):
        """
        Return ``PostureEstimator``'s options for the calibrated model (a dict).

        :attr:`left_unknown` with ``link_bias_std`` one per link (:attr:`link_bias_stds`),
        as posture_estimator reads the pump.yaml ``epp_calibrate`` writes:
        ``PostureEstimator(result.model, **result.estimator_options)``.
        """
        return {**self.left_unknown, 'link_bias_std': self.link_bias_stds}

    @property
    def success(self):
        """Return whether the calibration converged and is well determined."""
        return self.status == 'ok'


def _finite_ranges(values, shape, name):
    """Return a float copy of ``values`` of ``shape``, non-finite and negative -> NaN."""
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name} must be a numeric array of shape {shape}') from exc
    if array.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {array.shape}')
    with np.errstate(invalid='ignore'):
        array[~np.isfinite(array) | (array < 0)] = np.nan
    return array


def _angles(values, shape):
    """Return starting angles of ``shape``, radians; rows with a non-finite value -> NaN."""
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'start must be a numeric array of shape {shape}') from exc
    if array.shape != shape:
        raise ValueError(f'start must have shape {shape}, got {array.shape}')
    array[~np.all(np.isfinite(array), axis=1)] = np.nan
    return array


class _Problem:
    """
    The joint least squares: its parameters, residuals, Jacobian blocks and loss.

    Shared parameters ``x = x0 + basis @ q``: the free anchors' coordinates, then the tag
    offsets, then the anchor offsets; ``basis`` leaves out the gauge directions. The frames'
    rows are tag-anchor then tag-tag ranges; the anchor-anchor ranges (``pairs``, None
    without them) depend on the shared parameters only.
    """

    def __init__(self, model, ranges, tag_ranges, fixed, settings, pairs=None, survey=None):
        self.model = model
        p, m = model.n_sections, model.n_anchors
        self.p, self.m = p, m
        self.free = np.array([j for j in range(m) if j not in fixed], dtype=int)
        self.fixed = fixed
        self.n_pairs = 0        # the links' own offsets: the model's, until enabled
        self.n_x = 3 * self.free.size + p + m
        #: where x holds the offsets (tags', anchors', then the links' own once enabled)
        self.offset_index = 3 * self.free.size + np.arange(p + m)
        self.pair_index = np.zeros(0, dtype=int)
        self.length_index = np.zeros(0, dtype=int)      # the arm lengths, once enabled
        self.set_link_prior(0.0)
        self._rows(ranges, tag_ranges)
        self.pairs = pairs
        self.set_noise(settings)
        self.anchor_column = np.full(m, -1)
        self.anchor_column[self.free] = 3 * np.arange(self.free.size)
        self.offset_column = 3 * self.free.size + p + np.arange(m)
        tag_tag = tag_ranges is not None and np.isfinite(tag_ranges).any()
        self.basis, self.gauge = self._gauges(model, tag_tag, pairs is not None)
        self.x_given = self._configured(tag_tag or pairs is not None)
        self.x0 = self.x_given.copy()
        if survey is not None:      # the survey starts the anchors and the anchor offsets
            self.x0[:3 * self.free.size] = survey.anchors[self.free].ravel()
            self.x0[self.offset_column] = survey.anchor_offsets

    def _rows(self, ranges, tag_ranges):
        """Set up the frames' rows: measured (N, rows), mask and offsets' derivatives."""
        p, m = self.p, self.m
        self.ranges = ranges.reshape(len(ranges), p * m)
        tags = np.arange(p)
        self.link_tag = np.repeat(tags, m)
        self.link_anchor = np.tile(np.arange(m), p)
        if tag_ranges is not None:
            near, far = np.nonzero(~np.eye(p, dtype=bool))
            self.measured = np.hstack([self.ranges, tag_ranges[:, near, far]])
            self.near, self.far = near, far
        else:
            self.measured = self.ranges
            self.near = self.far = np.zeros(0, dtype=int)
        self.mask = np.isfinite(self.measured)
        self.n_links = p * m
        # d(range)/d(offsets): tag k and anchor j for a link, both tags for a tag-tag range.
        rows = self.measured.shape[1]
        self.offset_rows = np.zeros((rows, p + m))
        self.offset_rows[np.arange(p * m), self.link_tag] = 1.0
        self.offset_rows[np.arange(p * m), p + self.link_anchor] = 1.0
        self.offset_rows[p * m + np.arange(self.near.size), self.near] += 1.0
        self.offset_rows[p * m + np.arange(self.near.size), self.far] += 1.0
        self.known_offsets = np.r_[self.model.pair_offsets.ravel(), np.zeros(self.near.size)]

    def set_noise(self, settings):
        """
        Fit the ranges under the noise of ``settings`` from now on.

        A tag-anchor range r has sigma ``sqrt(sigma^2 + (eta r)^2)`` (r as measured), a
        tag-tag range ``tag_sigma``; all under the NLOS mixture.
        """
        links = np.hypot(settings.sigma, settings.eta * np.nan_to_num(
            self.measured[:, :self.n_links]))
        self.sigma = np.hstack([links, np.full((len(self.measured), self.near.size),
                                               settings.tag_sigma)])      # (N, rows)
        self.mixture = NlosMixture(settings.nlos_fraction, settings.nlos_gamma)
        self.blocked_prior = None       # (N, rows), or the mixture's fraction throughout
        self.blocked = None             # (N, rows) NLOS probabilities once judged
        self._losses = {}
        if self.pairs is not None:
            self.pairs.bind(self.mixture)

    def enable_link_terms(self, link_std, q):
        """
        Fit each link's own offset from now on, under ``N(0, link_std^2)``; return q so.

        They start from the model's (the known offsets until now), q's other parameters
        stay as they are.
        """
        own = self.model.pair_offsets.ravel()
        links = np.zeros((self.offset_rows.shape[0], own.size))
        links[np.arange(own.size), np.arange(own.size)] = 1.0
        self.offset_rows = np.hstack([self.offset_rows, links])
        self.known_offsets = np.zeros(self.offset_rows.shape[0])
        self.pair_index = self._append(own)
        self.offset_index = np.r_[self.offset_index, self.pair_index]
        self.n_pairs = own.size
        self.set_link_prior(link_std)
        return np.r_[q, np.zeros(own.size)]

    def enable_arm_lengths(self, q):
        """Fit the sections' lengths from now on, from the model's; return q so."""
        self.length_index = self._append(self.model.arm_lengths)
        return np.r_[q, np.zeros(self.p)]

    def _append(self, start):
        """Append parameters starting at ``start`` to x (and q); return their indices."""
        size = len(start)
        self.basis = np.block([[self.basis, np.zeros((self.n_x, size))],
                               [np.zeros((size, self.basis.shape[1])), np.eye(size)]])
        self.x_given, self.x0 = np.r_[self.x_given, start], np.r_[self.x0, start]
        self.n_x += size
        return np.arange(self.n_x - size, self.n_x)

    def arm_lengths(self, x):
        """Return the sections' lengths (p,) of ``x``: the model's unless fitted."""
        if not self.length_index.size:
            return self.model.arm_lengths
        return np.maximum(x[self.length_index], 1e-3)     # a trial step may overshoot

    def set_link_prior(self, link_std, correlation=NoiseCorrelation()):
        """
        Hold each link's own offset to ``N(0, link_std^2)`` from now on (metres).

        ``correlation``: the residuals' :class:`NoiseCorrelation`; the recording weighs its
        integrated autocorrelation time (``self.correlation``, frames) times less against
        the prior.
        """
        self.link_std = float(link_std)
        self.noise_correlation = correlation
        self.correlation = correlation.time
        self.pair_weight = self.correlation / self.link_std ** 2 if self.n_pairs else 0.0

    def located(self, tip=False):
        """
        Return whether each frame's ranges locate every tag but the tip's on its own (N,).

        With a tag between others unheard, the two sections about it have two solutions
        (an elbow either way) that merge as the elbow straightens: such a frame says
        little about the shared parameters and makes the joint fit crawl. ``tip``: the
        tip's too (an unheard tip leaves its section's angle to chance).
        """
        counts = self.mask[:, :self.n_links].reshape(-1, self.p, self.m).sum(axis=2)
        tags = counts if tip else counts[:, :-1]
        return np.all(tags >= 3, axis=1) & (counts.sum(axis=1) >= self.p + 1)

    def log_likelihood_ratio(self, scaled, frames):
        """Return log p(range | NLOS) / p(range | clear) (n, rows), 0 where not measured."""
        ratio = self.mixture.bind(self.sigma[frames]).log_likelihood_ratio(-scaled)
        return np.where(self.mask[frames], ratio, 0.0)

    def loss(self, frames):
        """Return the NLOS loss bound to the sigmas of ``frames`` (cached: fits reuse them)."""
        key = frames.tobytes()
        if key not in self._losses:
            if len(self._losses) > 8:
                self._losses.clear()
            prior = None if self.blocked_prior is None else self.blocked_prior[frames]
            self._losses[key] = self.mixture.bind(self.sigma[frames], prior)
        return self._losses[key]

    def _configured(self, split_measured):
        """Return the configured model's x; on the offsets' gauge unless data fix it."""
        p, m, n_anchor = self.p, self.m, 3 * self.free.size
        x = np.r_[self.model.anchors[self.free].ravel(), self.model.tag_offsets,
                  self.model.anchor_offsets]
        if not split_measured:
            split = x[n_anchor:n_anchor + p].sum() - x[n_anchor + p:].sum()
            x[n_anchor:n_anchor + p] -= split / (p + m)
            x[n_anchor + p:n_anchor + p + m] += split / (p + m)
        return x

    def _gauges(self, model, tag_tag, anchor_anchor):
        """Return the basis (n_x, n_q) of the shared parameters' changes, and its story."""
        p, m = self.p, self.m
        blocks, story = [], []
        axis_distance = np.linalg.norm(model.anchors[:, :2] - model.base[:2], axis=1)
        pinned = None
        if not any(axis_distance[j] > ANCHOR_SEPARATION for j in self.fixed):
            off_axis = [j for j in self.free if axis_distance[j] > ANCHOR_SEPARATION]
            pinned = off_axis[0]
            start = 'surveyed' if anchor_anchor else 'configured'
            story.append(f'anchor {pinned} keeps its {start} bearing about the slew axis '
                         '(no fixed anchor off the axis defines the x direction of the truck)')
        for j in self.free:
            if j == pinned:
                radial = np.r_[model.anchors[j, :2] - model.base[:2], 0.0]
                blocks.append(np.c_[radial / np.linalg.norm(radial), [0.0, 0.0, 1.0]])
            else:
                blocks.append(np.eye(3))
        if tag_tag or anchor_anchor:
            blocks.append(np.eye(p + m))
            which = ' and '.join(name for name, given in (('tag-tag', tag_tag),
                                                          ('anchor-anchor', anchor_anchor))
                                 if given)
            story.append(f'the {which} ranges split the link offsets between tags and '
                         'anchors: every offset is determined by data')
        else:
            split = np.r_[np.ones(p), -np.ones(m)] / np.sqrt(p + m)
            # Orthonormal basis of the offsets with sum(tag) == sum(anchor).
            blocks.append(np.linalg.svd(np.eye(p + m) - np.outer(split, split))[0][:, :-1])
            story.append('sum(tag_offsets) = sum(anchor_offsets): the split of the link '
                         'offsets nearest to zero')
        basis = np.zeros((self.n_x, sum(b.shape[1] for b in blocks)))
        row = column = 0
        for block in blocks:
            basis[row:row + block.shape[0], column:column + block.shape[1]] = block
            row, column = row + block.shape[0], column + block.shape[1]
        return basis, '; '.join(story)

    def unpack(self, x):
        """Return anchors (m, 3), tag offsets (p,), anchor offsets (m,) of ``x``."""
        anchors = self.model.anchors.copy()
        n_anchor = 3 * self.free.size
        anchors[self.free] = x[:n_anchor].reshape(-1, 3)
        return (anchors, x[n_anchor:n_anchor + self.p],
                x[n_anchor + self.p:n_anchor + self.p + self.m])

    def pair_offsets(self, x):
        """Return each link's own offset (p, m) of ``x``: the model's without link terms."""
        if not self.n_pairs:
            return self.model.pair_offsets
        return x[self.pair_index].reshape(self.p, self.m)

    def calibrated(self, q):
        """Return the model with the anchors and offsets of ``q``."""
        x = self.x0 + self.basis @ q
        anchors, tag_offsets, anchor_offsets = self.unpack(x)
        return self.model.with_calibration(anchors, anchor_offsets, tag_offsets,
                                           self.pair_offsets(x), self.arm_lengths(x))

    def evaluate(self, psi, x, frames, jacobian=True):
        """
        Scaled residuals of ``frames`` and, when asked, their Jacobian blocks.

        Returns
        -------
        scaled : ndarray, shape (n, rows)
            ``(predicted - measured) / sigma``, 0 where not measured.
        angle_jacobian : ndarray, shape (n, rows, p + 1)
        shared_jacobian : ndarray, shape (n, rows, n_q)

        """
        anchors = self.unpack(x)[0]
        model = self.model.with_calibration(arm_lengths=self.arm_lengths(x)) \
            if self.length_index.size else self.model
        joints = model.forward_kinematics(psi[:, 0], psi[:, 1:])           # (n, p, 3)
        vectors = np.concatenate([joints[:, self.link_tag] - anchors[self.link_anchor],
                                  joints[:, self.near] - joints[:, self.far]], axis=1)
        distances = np.linalg.norm(vectors, axis=-1)
        offsets = self.offset_rows @ x[self.offset_index] + self.known_offsets
        measured = self.measured[frames]
        mask = self.mask[frames]
        sigma = self.sigma[frames]
        scaled = np.where(mask, (distances + offsets - np.nan_to_num(measured)) / sigma, 0.0)
        if not jacobian:
            return scaled, None, None
        units = vectors / np.maximum(distances, 1e-12)[..., None]
        moved = model.joint_jacobian(psi[:, 0], psi[:, 1:])             # (n, p, 3, p + 1)
        links = self.n_links
        angle = np.empty(scaled.shape + (self.p + 1,))
        angle[:, :links] = np.einsum('nlc,nlcq->nlq', units[:, :links],
                                     moved[:, self.link_tag])
        angle[:, links:] = np.einsum('nlc,nlcq->nlq', units[:, links:],
                                     moved[:, self.near] - moved[:, self.far])
        shared = np.zeros(scaled.shape + (self.n_x,))
        free_links = np.flatnonzero(self.anchor_column[self.link_anchor] >= 0)
        for link in free_links:
            column = self.anchor_column[self.link_anchor[link]]
            shared[:, link, column:column + 3] = -units[:, link]
        shared[:, :, self.offset_index] = self.offset_rows
        if self.length_index.size:
            shared[:, :, self.length_index] = self._length_rows(psi, units)
        weight = mask / sigma
        return (scaled, angle * weight[..., None],
                (shared * weight[..., None]) @ self.basis)

    def _length_rows(self, psi, units):
        """Return d(range)/d(arm lengths) (n, rows, p): along each section's direction."""
        pitches = psi[:, 1:]
        direction = np.stack([np.cos(pitches) * np.cos(psi[:, :1]),
                              np.cos(pitches) * np.sin(psi[:, :1]), np.sin(pitches)],
                             axis=-1)                                   # (n, p sections, 3)
        # Joint k moves with the length of every section i <= k.
        moved = np.tril(np.ones((self.p, self.p)))[None, :, :, None] * direction[:, None]
        links = self.n_links
        rows = np.empty(units.shape[:2] + (self.p,))
        rows[:, :links] = np.einsum('nlc,nlic->nli', units[:, :links], moved[:, self.link_tag])
        rows[:, links:] = np.einsum('nlc,nlic->nli', units[:, links:],
                                    moved[:, self.near] - moved[:, self.far])
        return rows

    def robust(self, scaled, mask, frames, judged=True):
        """
        Return the robust cost (n,), its slope, IRLS weights and NLOS probabilities.

        Once the ranges are judged (:meth:`judge`), and with ``judged``: least squares with
        each range weighted by its probability of being clear. Otherwise the NLOS mixture
        on the excess ``-scaled``, with the chain's weights (``ChainMethod.loss``).
        """
        if judged and self.blocked is not None:
            blocked = self.blocked[frames]
            weights = np.where(mask, 1.0 - blocked, 0.0)
            return (0.5 * np.sum(weights * scaled ** 2, axis=1), weights * scaled, weights,
                    np.where(mask, blocked, 0.0))
        cost, slope, weights, nlos = irls(self.loss(frames), scaled, mask)
        return cost.sum(axis=1), slope, weights, nlos

    def judge(self, frames, prior, log_ratio):
        """
        Set the ranges of ``frames`` aside by their probability of being NLOS from now on.

        ``prior``, ``log_ratio`` (n, rows): each range's NLOS prior (from its link's other
        frames) and likelihood ratio (:meth:`log_likelihood_ratio`). Returns the fraction of
        the measured ranges judged otherwise than before (NLOS probability moved by > 0.5).
        """
        with np.errstate(divide='ignore'):
            logit = np.log(prior) - np.log1p(-prior) + log_ratio
        blocked = np.where(self.mask[frames], expit(logit), 0.0)
        if self.blocked is None:
            self.blocked = np.zeros(self.measured.shape)
            self.blocked_prior = np.full(self.measured.shape, self.mixture.fraction)
        before = self.blocked[frames].copy()
        self.blocked[frames] = blocked
        self.blocked_prior[frames] = prior      # the mixture's, for judging folds
        self._losses = {}
        mask = self.mask[frames]
        return float(np.mean(np.abs(blocked - before)[mask] > 0.5)) if mask.any() else 0.0

    def shared_terms(self, q):
        """
        Return the cost, gradient (n_q,) and information of the terms of ``q`` alone.

        The anchor-anchor ranges' (``AnchorPairs.terms``) and the links' own offsets'
        prior (:meth:`set_link_prior`). Also the anchor-anchor ranges' parts (None without
        them).
        """
        x = self.x0 + self.basis @ q
        cost, gradient, information, parts = self._anchor_terms(x)
        if self.n_pairs:
            prior = self.prior_terms(x, self.pair_weight)
            cost, gradient, information = (cost + prior[0], gradient + prior[1],
                                           information + prior[2])
        return cost, gradient, information, parts

    def anchor_pair_terms(self, q):
        """Return the anchor-anchor ranges' information (n_q, n_q) and parts (None: none)."""
        return self._anchor_terms(self.x0 + self.basis @ q)[2:]

    def _anchor_terms(self, x):
        """Return the anchor-anchor ranges' cost, gradient, information and parts of x."""
        if self.pairs is None:
            size = self.basis.shape[1]
            return 0.0, np.zeros(size), np.zeros((size, size)), None
        anchors, _, anchor_offsets = self.unpack(x)
        return self.pairs.terms(anchors, anchor_offsets, self.anchor_column,
                                self.offset_column, self.basis)

    def prior_terms(self, x, weight):
        """Return the links' offsets prior's cost, gradient and information in q."""
        link_offsets = x[self.pair_index]
        pairs = self.basis[self.pair_index]                 # (n_pairs, n_q)
        return (0.5 * weight * float(link_offsets @ link_offsets),
                weight * (pairs.T @ link_offsets), weight * (pairs.T @ pairs))


def _solve(chain, model, data, frame, prior, warm):
    """Return chain's (joints, info) of one frame of the recording, None when unsolved."""
    measurements, _ = data.measurements(model, frame)
    if not chain.enough_information(measurements):
        return None
    for _ in range(6):          # an exhausted search goes on where it stopped
        try:
            return chain.solve(measurements, prior, warm=warm)
        except SearchExhausted:
            continue
    return None


def _propagate(chain, model, data, frames, first):
    """
    Return the angles (n, p + 1) of ``frames`` by chain, each warm from the last.

    ``first`` (p + 1,): the first frame's starting angles; NaN rows: unsolved. Across a
    gap in time too: chain searches when its warm start fits badly, and a cold start with
    a model still off can take a wrong fold that fits it better.
    """
    psi = np.full((frames.size, model.n_sections + 1), np.nan)
    previous = model.forward_kinematics(first[0], first[1:])
    for index, frame in enumerate(frames):
        solved = _solve(chain, model, data, frame, previous, True)
        if solved is not None:
            previous = solved[0]
            psi[index] = np.r_[solved[1]['slew'], solved[1]['pitches']]
    return psi


def _hypotheses(chain, model, data, frame, most):
    """
    Return distinct postures (p + 1,) that fit the frame about as well, best first.

    A configuration that is off can make a wrong fold fit a frame best, and the warm
    start then follows it through the recording: each of these starts one recording.
    """
    solved = _solve(chain, model, data, frame, None, False)
    if solved is None:
        return []
    joints, info = solved
    measurements, _ = data.measurements(model, frame)
    residuals = Residuals(model, measurements, chain.noise)
    fits = [(chain.cost(np.r_[info['slew'], info['pitches']], residuals), joints)]
    for other in info['alternatives']:
        fit = chain.fit(np.r_[angles_from_joints(model, other)], residuals)
        fits.append((fit.cost, model.forward_kinematics(fit.psi[0], fit.psi[1:])))
    fits.sort(key=lambda fit: fit[0])
    kept = []
    for cost, candidate in fits:
        if cost > 4.0 * fits[0][0] + 25.0 or len(kept) == most:
            break
        if all(np.max(np.linalg.norm(candidate - other, axis=1)) > 0.5 for _, other in kept):
            kept.append((cost, candidate))
    return [np.r_[angles_from_joints(model, candidate)] for _, candidate in kept]


def _select(problem, chain, model, data, usable, hypotheses, max_iter, tol):
    """
    Fit every hypothesis on a subsample of the recording; return the best fit's parts.

    Returns
    -------
    first : ndarray, shape (p + 1,)
        The first frame's fitted angles.
    q : ndarray
        The shared parameters fitted.
    rms_before : float
        Metres, the range RMS of the chain's own choice with the configured model.
    fit : tuple
        The best fit's angles (n, p + 1) and its frames (n,).

    """
    stride = max(1, usable.size // SELECTION_FRAMES)
    subsample = usable[::stride]
    best, rms_before = None, float('nan')
    for number, hypothesis in enumerate(hypotheses):
        psi = _propagate(chain, model, data, subsample, hypothesis)
        solved = np.all(np.isfinite(psi), axis=1)
        if not solved.any():
            continue
        frames, psi = subsample[solved], psi[solved]
        if number == 0:
            rms_before = _range_rms(problem, psi, problem.x_given, frames)
        psi, q, cost, _, _ = least_squares(problem, psi, np.zeros(problem.basis.shape[1]),
                                           frames, min(max_iter, SELECTION_ITERATIONS), tol)
        score = cost / problem.mask[frames].sum()
        if best is None or score < best[0]:
            best = (score, psi, q, frames)
    if best is None:
        raise ValueError('no frame of the recording could be solved: nothing to calibrate')
    _, psi, q, frames = best
    return psi[0], q, rms_before, (psi, frames)


def _range_rms(problem, psi, x, frames):
    """Return the RMS of measured less predicted tag-anchor ranges of ``frames``, metres."""
    scaled = problem.evaluate(psi, x, frames, jacobian=False)[0][:, :problem.n_links]
    mask = problem.mask[frames, :problem.n_links]
    metres = scaled * problem.sigma[frames][:, :problem.n_links]
    return float(np.sqrt(np.mean(metres[mask] ** 2))) if mask.any() \
        else float('nan')


@dataclass(frozen=True)
class _Recording:
    """The frames' ranges, and when they were taken."""

    ranges: np.ndarray          #: (N, p, m) metres
    tag_ranges: np.ndarray      #: (N, p, p) metres, or None
    times: np.ndarray           #: (N,) the stamps, or the frames' numbers without them

    @classmethod
    def of(cls, ranges, tag_ranges, stamps):
        """Return the recording, its frames one period apart without ``stamps``."""
        times = np.arange(len(ranges), dtype=float) if stamps is None else stamps
        return cls(ranges, tag_ranges, times)

    def measurements(self, model, frame):
        """Return ``Measurements.clean`` of a frame."""
        return Measurements.clean(model, self.ranges[frame],
                                  None if self.tag_ranges is None else self.tag_ranges[frame])


def _stamps(values, count):
    """Return the stamps as floats (count,), None for None; in time order or ValueError."""
    if values is None:
        return None
    try:
        stamps = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'stamps must be a numeric array of shape ({count},)') from exc
    if stamps.shape != (count,):
        raise ValueError(f'stamps must have shape ({count},), got {stamps.shape}')
    if not np.all(np.isfinite(stamps)):
        raise ValueError('stamps must be finite')
    if np.any(np.diff(stamps) < 0):
        raise ValueError('stamps must be in time order: sort the frames by their stamps')
    return stamps


@dataclass(frozen=True)
class _Settings:
    """What every stage of :func:`calibrate` needs to know besides the data: the noise."""

    sigma: float
    eta: float
    tag_sigma: float
    nlos_fraction: float
    nlos_gamma: float
    max_iter: int
    tol: float
    nlos_duration: float = None     #: in the stamps' unit; None: learned

    def chain(self, model):
        """Return the chain estimator that starts (or restarts) the frames' angles."""
        return ChainMethod(model, sigma=self.sigma, eta=self.eta, tag_sigma=self.tag_sigma,
                           nlos_fraction=self.nlos_fraction, nlos_gamma=self.nlos_gamma)

    def noise(self):
        """Return the tag-anchor range noise as a ``RangeNoiseEstimate``."""
        return RangeNoiseEstimate(self.sigma, self.eta, self.nlos_fraction, self.nlos_gamma)


def _learned_noise(problem, psi, q, frames, settings):
    """
    Return ``settings`` with the range noise learned from the joint fit's residuals.

    ``core.noise_learning.NoiseLearner`` (EM under the NLOS mixture, sigma growing with
    the range) over every frame's tag-anchor residuals at once; the settings as they were
    with too few residuals.
    """
    n = problem.n_links
    x = problem.x0 + problem.basis @ q
    scaled = problem.evaluate(psi, x, frames, jacobian=False)[0][:, :n]
    mask = problem.mask[frames][:, :n]
    excess = np.where(mask, -scaled * problem.sigma[frames][:, :n], np.nan)
    measured = problem.measured[frames][:, :n]
    dof = problem.p + 1
    counts = mask.sum(axis=1)
    links = int(counts[counts > dof].sum())
    if links == 0:
        return settings
    # Settled, hence fitted, exactly when the last frame is in.
    learner = NoiseLearner(settings.noise(), window=frames.size, every=frames.size + 1,
                           settle_links=links)
    for row in range(frames.size):
        learner.observe(excess[row], measured[row], dof)
    if not learner.settled:
        return settings
    learned = learner.estimate
    return replace(settings, sigma=learned.sigma, eta=learned.eta,
                   nlos_fraction=learned.nlos_fraction, nlos_gamma=learned.nlos_gamma)


def _survey(model, anchor_ranges, fixed, anchor_sigma, settings, prior_sigma):
    """Return the anchor-anchor ranges' terms and the survey, (None, None) without them."""
    if anchor_ranges is None:
        return None, None
    rounds = anchor_range_rounds(anchor_ranges, model.n_anchors)
    survey = survey_anchors(model, rounds, fixed_anchors=fixed, sigma=anchor_sigma,
                            prior_sigma=prior_sigma, nlos_fraction=settings.nlos_fraction,
                            nlos_gamma=settings.nlos_gamma)
    mixture = NlosMixture(settings.nlos_fraction, settings.nlos_gamma)
    return AnchorPairs(rounds, anchor_sigma, mixture), survey


def _start(problem, data, start, settings, hypotheses, learn_noise):
    """
    Return every frame's starting angles (N, p + 1) (NaN: unused), q, RMS before, settings.

    Without ``start``: chain from the best of the first frame's ``hypotheses`` (fitted on a
    subsample with the configured model), then through the recording warm-started. With
    ``learn_noise`` the hypotheses are ranked again under the noise learned from the best
    one's fit: under a noise far from the data's (a tip's ranges three times noisier than
    told) a wrong fold of a section, with its tag's offset off by a metre, can fit best.
    """
    count, p, m = data.ranges.shape
    model = problem.model
    q = np.zeros(problem.basis.shape[1])
    enough = problem.mask[:, :p * m].sum(axis=1) >= p + 1
    if start is not None:
        psi_all = _angles(start, (count, p + 1))
        frames = np.flatnonzero(np.all(np.isfinite(psi_all), axis=1) & enough)
        rms = _range_rms(problem, psi_all[frames], problem.x_given, frames) \
            if frames.size else float('nan')
        return psi_all, q, rms, settings
    chain = settings.chain(model)
    usable, starts = np.flatnonzero(enough), []
    # The first frame with every tag located that chain can solve (a tag may be silent for
    # seconds, and a start at a wrong fold is followed through the recording).
    located = problem.located(tip=True)
    for frame in np.flatnonzero(enough & (located if located.any() else problem.located())):
        starts = _hypotheses(chain, model, data, frame, hypotheses)
        if starts:
            usable = usable[usable >= frame]
            break
    first, q, rms_before, (psi, frames) = _select(problem, chain, model, data, usable, starts,
                                                  settings.max_iter, settings.tol)
    if learn_noise:
        settings = _learned_noise(problem, psi, q, frames, settings)
        problem.set_noise(settings)
        first, q, _, _ = _select(problem, settings.chain(model), model, data, usable, starts,
                                 settings.max_iter, settings.tol)
    started = problem.calibrated(q)
    psi_all = np.full((count, p + 1), np.nan)
    psi_all[usable] = _propagate(settings.chain(started), started, data, usable, first)
    return psi_all, q, rms_before, settings


def _frame_costs(problem, psi, q, frames):
    """Return each frame's robust cost (n,) at ``psi`` (n, p + 1) and ``q``."""
    scaled = problem.evaluate(psi, problem.x0 + problem.basis @ q, frames, jacobian=False)[0]
    return problem.robust(scaled, problem.mask[frames], frames, judged=False)[0]


def _lost_frames(problem, psi, q, frames):
    """
    Return the indices of the frames the joint fit leaves far off, likely at a wrong fold.

    The NLOS loss grows only linearly far out, so a wrong fold costs a few times the
    typical frame per link, not orders of magnitude.
    """
    cost = _frame_costs(problem, psi, q, frames)
    per_link = cost / np.maximum(problem.mask[frames].sum(axis=1), 1)
    return np.flatnonzero(per_link > max(LOST_FRAME_COST, 3 * np.median(per_link)))


def _restarted(problem, data, psi, q, frames, settings, lost):
    """
    Return the angles (n, p + 1) with the frames chain now fits better, and how many.

    Chain with the calibrated model solves the lost frames from scratch and goes through
    the whole recording again warm-started (a fold taken wrongly at the start, or after
    a silent tag, is kept by the warm start until the model is right); each frame keeps
    the lowest cost of the three, its fit's angles unless another is lower by
    :data:`RESTART_GAIN`.
    """
    try:
        calibrated = problem.calibrated(q)
    except ValueError:      # values no pump has: left to the verdict
        return psi, 0
    chain = settings.chain(calibrated)
    cold = psi.copy()
    for index in lost:
        solved = _solve(chain, calibrated, data, frames[index], None, False)
        if solved is not None:
            cold[index] = np.r_[solved[1]['slew'], solved[1]['pitches']]
    warm = _propagate(chain, calibrated, data, frames, psi[0])
    warm = np.where(np.isfinite(warm), warm, psi)
    costs = np.stack([_frame_costs(problem, candidate, q, frames)
                      for candidate in (psi, cold, warm)])
    costs[0] -= RESTART_GAIN        # the fit's own angles but for a clearly better fold
    best = np.argmin(costs, axis=0)
    chosen = np.choose(best[:, None], (psi, cold, warm))
    return chosen, int(np.count_nonzero(best))


def _blockage(problem, data, psi, q, frames, settings):
    """
    Judge each range: its NLOS probability, its prior from its link's other frames.

    The prior comes from ``core.blockage`` (a blocked link stays blocked), its duration
    learned unless given.

    Returns the chain of the links' NLOS states (None without NLOS) and the fraction of
    the ranges judged otherwise than before (``_Problem.judge``).
    """
    if problem.mixture.fraction == 0.0:
        return None, 0.0
    scaled = problem.evaluate(psi, problem.x0 + problem.basis @ q, frames, jacobian=False)[0]
    log_ratio = problem.log_likelihood_ratio(scaled, frames)
    elapsed = np.diff(data.times[frames])
    if settings.nlos_duration is None:
        chain = BlockageChain.learn(problem.mixture.fraction, log_ratio, elapsed)
    else:
        chain = BlockageChain(problem.mixture.fraction, settings.nlos_duration)
    return chain, problem.judge(frames, chain.priors(log_ratio, elapsed), log_ratio)


def _joint_fit(problem, data, psi, q, frames, settings, refits):
    """
    Return the joint fit's angles, q, iterations, convergence and the links' NLOS chain.

    The first fit is under the NLOS mixture, each range on its own. After each fit the
    ranges are judged (:func:`_blockage`: each range's probability of being NLOS, given its
    link's other frames too, since blockages persist), to be set aside by it in the next
    fit; chain with the calibrated model restarts the frames (:func:`_restarted`: a chain
    start at a wrong fold); while either changes anything, the fit is repeated, at most
    ``refits`` times.
    """
    total, blockage = 0, None
    for round_ in range(refits + 1):
        psi, q, _, iterations, converged = least_squares(problem, psi, q, frames,
                                                         settings.max_iter, settings.tol)
        total += iterations
        if round_ == refits:
            break
        blockage, change = _blockage(problem, data, psi, q, frames, settings)
        lost = _lost_frames(problem, psi, q, frames)
        psi, changed = _restarted(problem, data, psi, q, frames, settings, lost)
        if changed == 0 and change < JUDGED_OTHERWISE:
            break
    return psi, q, total, converged, blockage


def _uncertainty(problem, psi, q, frames):
    """
    Return the covariance of x, the condition, residual scale and the NLOS probabilities.

    The shared parameters' information with the angles eliminated, divided by the
    residuals' integrated autocorrelation time (``problem.correlation``: correlated frames
    weigh as fewer independent ones, as the fit weighs them against the links' prior),
    plus the anchor-anchor ranges' and the links' offsets prior's. The covariance is that
    information's inverse about the spread of the fit's gradient under the residuals'
    :class:`NoiseCorrelation` (each link's reduced Jacobian rows correlated in time):
    a parameter told by slow swings of the geometry is told by few independent frames, of
    whatever the residuals' time. Scaled by the residual variance; inf along what it misses.
    """
    p = problem.p
    x = problem.x0 + problem.basis @ q
    scaled, angle, shared = problem.evaluate(psi, x, frames)
    _, slope, weights, nlos_links = problem.robust(scaled, problem.mask[frames], frames)
    blocks, coupling, shared_block, _, _ = normal_equations(angle, shared, slope, weights)
    pair_information, pair_parts = problem.anchor_pair_terms(q)
    reduced, inverse = eliminate(blocks, coupling, shared_block, pseudo=True)
    prior = pair_information
    if problem.n_pairs:
        prior = prior + problem.prior_terms(x, 1.0 / problem.link_std ** 2)[2]
    information = reduced / problem.correlation + prior
    squares, count = np.sum(weights * scaled ** 2), float(weights.sum())
    if pair_parts is not None:
        squares += np.sum(pair_parts[1] * pair_parts[0] ** 2)
        count += float(pair_parts[1].sum())
    dof = max(count - frames.size * (p + 1) - q.size, 1.0)
    residual_scale = float(np.sqrt(squares / dof))
    covariance_q, condition = scaled_covariance(information, residual_scale)
    rows = weights[..., None] * (shared - angle @ (inverse @ coupling))     # (n, links, q)
    spread = (np.einsum('nlq,nlr->qr', rows, problem.noise_correlation.correlate(rows))
              / problem.correlation ** 2 + prior)
    covariance_q = _sandwich(covariance_q, spread, residual_scale)
    if problem.n_pairs:     # how well the recording excites the devices' parameters
        condition = scaled_covariance(_marginal(information, problem.n_pairs), 1.0)[1]
    with np.errstate(invalid='ignore'):
        covariance = problem.basis @ np.nan_to_num(covariance_q, posinf=0.0) @ problem.basis.T
    undetermined = problem.basis[:, np.isinf(np.diag(covariance_q))].any(axis=1)
    covariance[undetermined, :] = np.inf
    covariance[:, undetermined] = np.inf
    return covariance, condition, residual_scale, nlos_links


def _sandwich(covariance, spread, scale):
    """Return ``C spread C / scale^2`` for C = ``covariance`` (inf rows and columns kept)."""
    known = np.isfinite(np.diag(covariance))
    inner = covariance[np.ix_(known, known)]
    result = covariance.copy()
    result[np.ix_(known, known)] = inner @ spread[np.ix_(known, known)] @ inner / scale ** 2
    return result


def _residual_spread(problem, psi, q, frames):
    """
    Return each link's sum of squared scaled residuals and what it would be in a fit (p, m).

    Over the clear tag-anchor ranges (IRLS weights); what a fit leaves is each range's
    ``sigma^2 (1 - h)``, h its leverage on its frame's angles (the shared parameters'
    is small beside it).
    """
    n = problem.n_links
    scaled, angle, _ = problem.evaluate(psi, problem.x0 + problem.basis @ q, frames)
    weights = problem.robust(scaled, problem.mask[frames], frames)[2]
    blocks = np.einsum('nla,nlb->nab', angle * weights[..., None], angle)
    inverse = np.linalg.pinv(blocks, rcond=1e-10, hermitian=True)
    leverage = weights * np.einsum('nla,nab,nlb->nl', angle, inverse, angle)
    squares = np.sum(weights * scaled ** 2, axis=0)[:n].reshape(problem.p, problem.m)
    expected = np.sum(weights - leverage, axis=0)[:n].reshape(problem.p, problem.m)
    return squares, np.maximum(expected, 0.0)


def _marginal(information, trailing):
    """Return the information of all but the ``trailing`` parameters, those eliminated."""
    kept, own = information[:-trailing, :-trailing], information[-trailing:, -trailing:]
    coupling = information[:-trailing, -trailing:]
    return kept - coupling @ np.linalg.solve(own, coupling.T)


def _correlation(problem, psi, q, frames):
    """
    Return the tag-anchor residuals' :class:`NoiseCorrelation`.

    Over the clear ranges and every measured one within :data:`NOISE_REACH` standard
    deviations: on a moving body the noise's slow swings look like blockage, and leaving
    out all that the fit judged blocked took them out of the estimate (the time read 24
    frames for 37; 30 with them), while a blocked range's excess is mostly far beyond.
    """
    n = problem.n_links
    scaled = problem.evaluate(psi, problem.x0 + problem.basis @ q, frames, jacobian=False)[0]
    weights = problem.robust(scaled, problem.mask[frames], frames)[2]
    scaled, within = scaled[:, :n], problem.mask[frames][:, :n]
    counted = (weights[:, :n] > 0.5) | (within & (np.abs(scaled) < NOISE_REACH))
    return fit_noise_correlation(scaled, counted)


def _link_terms(problem, psi, q, frames, settings, learn):
    """
    Fit with each link's own offset under its prior; with ``learn``, the prior's size too.

    The residuals' autocorrelation sets how much the recording weighs against the prior;
    the size is learned by expectation-maximisation (the mean of each link offset's
    squared estimate plus its variance), at least :data:`LINK_STD_FLOOR`. Returns the
    angles, q, the iterations and whether the last fit converged.
    """
    iterations, converged = 0, True
    if not problem.n_pairs:
        problem.set_link_prior(0.0, _correlation(problem, psi, q, frames))
        return psi, q, iterations, converged
    for _ in range(LINK_ROUNDS):
        problem.set_link_prior(problem.link_std, _correlation(problem, psi, q, frames))
        psi, q, _, more, converged = least_squares(problem, psi, q, frames, settings.max_iter,
                                                   settings.tol)
        iterations += more
        if not learn:
            break
        covariance, _, scale, _ = _uncertainty(problem, psi, q, frames)
        own = problem.pair_index
        x = problem.x0 + problem.basis @ q
        # The posterior under the noise as told: a misfit's scale is not the links'.
        variance = np.nan_to_num(np.diag(covariance)[own] / scale ** 2,
                                 posinf=problem.link_std ** 2)
        learned = max(float(np.sqrt(np.mean(x[own] ** 2 + variance))), LINK_STD_FLOOR)
        change = abs(learned / problem.link_std - 1.0)
        problem.set_link_prior(learned, problem.noise_correlation)
        if change < 0.05:
            break
    return psi, q, iterations, converged


def _anchor_rms(problem, q):
    """Return the RMS of measured less fitted anchor-anchor ranges, metres (NaN: none)."""
    if problem.pairs is None:
        return float('nan')
    anchors, _, anchor_offsets = problem.unpack(problem.x0 + problem.basis @ q)
    scaled = problem.pairs.residuals(anchors, anchor_offsets, problem.anchor_column,
                                     problem.offset_column, problem.n_x)[0]
    return float(np.sqrt(np.mean(scaled[problem.pairs.mask] ** 2))) * problem.pairs.sigma


def calibrate(model, ranges, *, stamps=None, tag_ranges=None, anchor_ranges=None,
              fixed_anchors=(0,), sigma=DEFAULT_NOISE.sigma, eta=DEFAULT_NOISE.eta,
              tag_sigma=None, anchor_sigma=None, prior_sigma=0.5,
              nlos_fraction=DEFAULT_NOISE.nlos_fraction, nlos_gamma=DEFAULT_NOISE.nlos_gamma,
              nlos_duration=None,
              learn_noise=False, start=None, max_iter=100, tol=1e-10, refits=3,
              hypotheses=4, anchor_tolerance=ANCHOR_TOLERANCE,
              offset_tolerance=OFFSET_TOLERANCE, link_std=None, fit_arm_lengths=False):
    """
    Calibrate the free anchors' positions and the device range offsets from a recording.

    Parameters
    ----------
    model : BoomModel
        The boom as configured: its anchors and offsets are the start, its fixed anchors
        and geometry are kept.
    ranges : array_like, shape (N, p, m)
        Tag-anchor ranges of each frame as the modules report them, metres; NaN (or any
        non-finite or negative value) where missing. The boom should move: a slew sweep
        and some luffing locate the anchors.
    stamps : array_like, shape (N,), optional
        When each frame was taken, seconds, in time order (ValueError otherwise); None:
        frames one period apart. How long a blocked link stays blocked is reckoned in them
        (across a gap, a link's states are independent).
    tag_ranges : array_like, shape (N, p, p), optional
        Tag-tag ranges, metres, NaN where missing; they also split the link offsets
        between tags and anchors (the gauge, see the module's description).
    anchor_ranges : array_like, shape (K, m, m), optional
        K >= 1 rounds of anchor-anchor ranges, metres (``[k, i, j]``: anchor i's range to
        anchor j, ``||a_i - a_j|| + o_i + o_j``), NaN where missing, taken at any time of
        the recording (the anchors do not move). They survey the free anchors and the
        anchor offsets before the joint fit (:func:`core.survey.survey_anchors`, the
        result's ``survey``), enter the joint fit as residuals, and fix the split of the
        link offsets between tags and anchors by data.
    fixed_anchors : sequence of int
        Anchors on the truck body (turret, cab) whose configured positions, with the
        boom's base and slew axis, define the truck frame; the others are fitted.
    sigma, eta : float
        Range noise: a tag-anchor range r has standard deviation ``sqrt(sigma^2 + (eta
        r)^2)`` metres (``eta=0``: sigma throughout), as the estimators' noise model.
    tag_sigma, anchor_sigma : float, optional
        Tag-tag and anchor-anchor range standard deviations, metres; None: ``sigma``.
    prior_sigma : float
        Metres per axis: how far the survey lets a free anchor be from its configured
        position where the anchor-anchor ranges do not see it (see ``survey_anchors``).
    nlos_fraction, nlos_gamma : float
        The NLOS mixture (prior blocked fraction, mean excess in metres) the ranges are
        fitted under, as the chain estimator's; ``nlos_fraction=0``: plain least squares.
    nlos_duration : float, optional
        How long a blocked link stays blocked on average, seconds (frame periods without
        ``stamps``): each range is judged under the NLOS probability its link's other
        frames give it (``core.blockage``). None: learned from the recording (the most
        likely of ``core.blockage.DURATIONS``); 0: every frame on its own.
    learn_noise : bool
        After the joint fit, learn the tag-anchor range noise (``sigma``, ``eta`` and the
        NLOS mixture) from its residuals (``core.noise_learning``) and fit again under it:
        for a site whose noise is not known (it grows with distance, links stay blocked).
        The result's ``range_noise`` is what the fit used.
    start : array_like, shape (N, p + 1), optional
        Each frame's starting angles (slew, pitches), radians, NaN rows skipped; default:
        chain fits of each frame, warm-started from the previous one, from the best of
        ``hypotheses`` starts (below).
    max_iter : int
        Levenberg–Marquardt iterations per solve.
    tol : float
        Stop when no parameter moves more than this (radians or metres).
    refits : int
        Rounds in which frames the joint fit leaves far off (a chain start at a wrong
        fold) are solved again by chain with the calibrated model, and the joint fit
        repeated.
    hypotheses : int
        Most postures of the first frame tried as the recording's start: with the
        configuration off, a wrong fold can fit a frame best (and chain then follows it);
        each is fitted on a subsample, and the best fit starts the whole recording.
    anchor_tolerance, offset_tolerance : float
        Metres: anchors (std along their worst direction) and link offsets (std) less
        certain than these are reported as poorly determined.
    link_std : float, optional
        Metres: real links have an offset of their own beyond their tag's and anchor's
        (antenna orientations, the path between the two devices); each is fitted under
        the prior ``N(0, link_std^2)`` (the result's ``pair_offsets``), so that what the
        devices' offsets cannot explain is not pushed into the anchors. None: the size is
        learned from the recording (from ``LINK_STD_START``); 0: the devices' offsets
        alone.
    fit_arm_lengths : bool
        Fit the sections' lengths too, from the model's, once the rest has settled: for a
        boom whose lengths are not known to centimetres (a misfit verdict that names a
        section). Along the lines of sight a length looks like its tag's offset, so it
        is determined only where the recording sees the section from several sides (the
        result's ``arm_length_std``, and the verdict, say how well).

    Returns
    -------
    CalibrationResult
        ``rms_before`` is the configured model's, also with a survey.

    Raises
    ------
    ValueError
        On a wrong shape, bad fixed anchors, a recording without a usable frame, or
        anchor-anchor ranges the survey refuses.

    """
    began = time.perf_counter()
    p, m = model.n_sections, model.n_anchors
    if link_std is not None and not float(link_std) >= 0.0:
        raise ValueError(f'link_std must be >= 0 metres or None, got {link_std}')
    count = len(ranges) if np.ndim(ranges) == 3 else 0
    ranges = _finite_ranges(ranges, (count, p, m), 'ranges')
    stamps = _stamps(stamps, count)
    if nlos_duration is not None and not float(nlos_duration) >= 0.0:
        raise ValueError(f'nlos_duration must be >= 0, got {nlos_duration}')
    if tag_ranges is not None:
        tag_ranges = _finite_ranges(tag_ranges, (count, p, p), 'tag_ranges')
        tag_ranges[:, np.arange(p), np.arange(p)] = np.nan
    fixed = fixed_indices(fixed_anchors, m)
    tag_sigma = sigma if tag_sigma is None else tag_sigma
    anchor_sigma = sigma if anchor_sigma is None else anchor_sigma
    settings = _Settings(float(sigma), float(eta), float(tag_sigma), float(nlos_fraction),
                         float(nlos_gamma), max_iter, tol,
                         None if nlos_duration is None else float(nlos_duration))
    pairs, survey = _survey(model, anchor_ranges, fixed, float(anchor_sigma), settings,
                            prior_sigma)
    problem = _Problem(model, ranges, tag_ranges, fixed, settings, pairs, survey)
    if not problem.located().any():
        raise ValueError('no frame in which every tag but the tip has three or more ranges: '
                         'nothing to calibrate (is a tag dead?)')
    data = _Recording.of(ranges, tag_ranges, stamps)
    psi_all, q, rms_before, settings = _start(problem, data, start, settings, hypotheses,
                                              learn_noise)
    frames = np.flatnonzero(np.all(np.isfinite(psi_all), axis=1) & problem.located())
    if frames.size == 0:
        raise ValueError('no frame of the recording could be solved: nothing to calibrate')
    psi, q, iterations, converged, blockage = _joint_fit(problem, data, psi_all[frames], q,
                                                         frames, settings, refits)
    if learn_noise:
        settings = _learned_noise(problem, psi, q, frames, settings)
        problem.set_noise(settings)
        psi, q, more, converged, blockage = _joint_fit(problem, data, psi, q, frames,
                                                       settings, refits)
        iterations += more
    if fit_arm_lengths:
        q = problem.enable_arm_lengths(q)
        psi, q, more, converged, blockage = _joint_fit(problem, data, psi, q, frames,
                                                       settings, refits)
        iterations += more
    if link_std is None or link_std > 0:
        q = problem.enable_link_terms(LINK_STD_START if link_std is None else link_std, q)
    psi, q, more, converged = _link_terms(problem, psi, q, frames, settings, link_std is None)
    iterations += more
    return _result(problem, psi, q, frames, count, survey, {
        'rms_before': rms_before, 'iterations': iterations, 'converged': converged,
        'began': began, 'max_iter': max_iter, 'anchor_tolerance': anchor_tolerance,
        'offset_tolerance': offset_tolerance, 'noise': settings.noise(),
        'nlos_duration': 0.0 if blockage is None else blockage.duration})


def _result(problem, psi, q, frames, count, survey, facts):
    """Return the :class:`CalibrationResult` of the joint fit's solution."""
    p, m, model = problem.p, problem.m, problem.model
    x = problem.x0 + problem.basis @ q
    anchors, tag_offsets, anchor_offsets = problem.unpack(x)
    pair_offsets, arm_lengths = problem.pair_offsets(x), problem.arm_lengths(x)
    covariance, condition, residual_scale, nlos_links = _uncertainty(problem, psi, q, frames)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    n_anchor = 3 * problem.free.size
    anchor_std = np.zeros((m, 3))
    anchor_std[problem.free] = std[:n_anchor].reshape(-1, 3)
    poorly, advice = poorly_determined(problem, covariance, condition,
                                       facts['anchor_tolerance'], facts['offset_tolerance'])
    wandered = False
    try:
        calibrated = model.with_calibration(anchors, anchor_offsets, tag_offsets, pair_offsets,
                                            arm_lengths)
    except ValueError as exc:       # values no pump has: the recording did not pin them
        calibrated, wandered = model, True
        poorly = poorly + ['the recording']
        advice = advice + [f'the fit wandered to values no pump has ({exc}); record the '
                           'boom slewing and luffing every section']
    rms_after = _range_rms(problem, psi, problem.x0 + problem.basis @ q, frames)
    misfits = (misfit(*_residual_spread(problem, psi, q, frames), problem.correlation)
               + implausible(tag_offsets[:, None] + anchor_offsets + pair_offsets))
    status, message = verdict(wandered, facts['converged'], poorly, advice,
                              facts['max_iter'], frames, facts['rms_before'], rms_after,
                              misfits)
    postures = np.full((count, p + 1), np.nan)
    postures[frames] = psi
    nlos = np.zeros((count, p, m))
    nlos[frames] = nlos_links[:, :p * m].reshape(-1, p, m)
    used = np.zeros(count, bool)
    used[frames] = True
    return CalibrationResult(
        status=status, message=message, model=calibrated, anchors=anchors,
        anchor_offsets=anchor_offsets, tag_offsets=tag_offsets,
        link_offsets=tag_offsets[:, None] + anchor_offsets[None, :] + pair_offsets,
        pair_offsets=pair_offsets, link_std=problem.link_std,
        correlation=problem.correlation, anchor_std=anchor_std, arm_lengths=arm_lengths,
        arm_length_std=std[problem.length_index] if problem.length_index.size
        else np.zeros(p),
        anchor_offset_std=std[n_anchor + p:n_anchor + p + m],
        tag_offset_std=std[n_anchor:n_anchor + p],
        link_offset_std=link_offset_std(problem, covariance),
        common_offset_std=common_offset_std(problem, covariance),
        rms_before=facts['rms_before'],
        rms_after=rms_after, residual_scale=residual_scale, condition=condition,
        poorly_determined=poorly, gauge=problem.gauge, converged=facts['converged'],
        iterations=facts['iterations'], frames_used=used, postures=postures, nlos=nlos,
        covariance=covariance, seconds=time.perf_counter() - facts['began'], survey=survey,
        anchor_rms_after=_anchor_rms(problem, q), range_noise=facts['noise'],
        nlos_duration=facts['nlos_duration'])
