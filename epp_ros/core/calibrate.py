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
leaves a small dense system in the shared parameters. Levenberg–Marquardt steps that system
with the analytic Jacobian (``BoomModel.joint_jacobian``).

Ranges are fitted under the chain estimator's NLOS mixture (``core.nlos``), by iteratively
reweighted least squares: the maximum-likelihood estimate when some links are blocked. A
symmetric robust loss (Huber, soft-L1) would not do here: NLOS excesses are one-sided, so
a symmetric loss leaves part of their mean in every estimated location parameter, and the
range offsets are exactly location parameters.

Gauges. The fixed anchors (``fixed_anchors``: on the truck body) define the truck frame
together with the boom's base and slew axis. Two changes of the parameters leave every
range the same, and are fixed by convention:

- a constant added to every tag offset and taken from every anchor offset: without tag-tag
  ranges the split is fixed by ``sum(tag_offsets) == sum(anchor_offsets)``, the split
  nearest to zero (the likeliest when every device's offset is drawn alike). The link
  offsets ``tag_offsets[k] + anchor_offsets[j]`` do not depend on it: they are what the
  ranges determine. Tag-tag ranges measure ``tag_offsets[k] + tag_offsets[l]`` and fix
  the split themselves.
- when every fixed anchor is on the slew axis (the turret's pivot alone), a rotation of
  the free anchors about the axis, with every frame's slew: the first free anchor off the
  axis then keeps its configured bearing (it defines the truck's x direction).
"""
from dataclasses import dataclass, field
import operator
import time

import numpy as np

from .chain import angles_from_joints, ChainMethod, SearchExhausted
from .measurements import Measurements, Residuals
from .model import ANCHOR_SEPARATION
from .nlos import NlosMixture

__all__ = ['CalibrationResult', 'calibrate']

#: Metres: calibrated anchors less certain than this (std along their worst direction)
#: are reported as poorly determined; the issue's target accuracy.
ANCHOR_TOLERANCE = 0.05

#: Metres: link offsets less certain than this are reported as poorly determined.
OFFSET_TOLERANCE = 0.03

#: Frames of the subsample each starting hypothesis is fitted on.
SELECTION_FRAMES = 150

#: Condition number (of the shared parameters' information, normalised to unit diagonal)
#: above which a recording is reported as poorly exciting, whatever its length.
CONDITION_LIMIT = 1e4


@dataclass
class CalibrationResult:
    """
    What :func:`calibrate` found, how well it is determined, and the verdict.

    Standard deviations come from the Jacobian at the solution: the inverse of the
    information of the shared parameters (the angles marginalised), scaled by the
    residual variance; zero for what the gauges fix.
    """

    status: str                 #: ``"ok"``, ``"poorly_excited"`` or ``"not_converged"``
    message: str                #: the verdict, with what is poorly determined and why
    model: object               #: the calibrated BoomModel
    anchors: np.ndarray         #: (m, 3) metres
    anchor_offsets: np.ndarray  #: (m,) metres
    tag_offsets: np.ndarray     #: (p,) metres
    link_offsets: np.ndarray    #: (p, m) metres, tag + anchor: what the ranges determine
    anchor_std: np.ndarray      #: (m, 3) metres per axis (0 for fixed anchors)
    anchor_offset_std: np.ndarray   #: (m,) metres (depends on the gauge)
    tag_offset_std: np.ndarray  #: (p,) metres (depends on the gauge)
    link_offset_std: np.ndarray     #: (p, m) metres
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
    covariance: np.ndarray = None   #: of (free anchors' xyz, tag offsets, anchor offsets)
    seconds: float = 0.0            #: computation time

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


def _fixed_indices(fixed_anchors, m):
    try:
        fixed = tuple(operator.index(j) for j in fixed_anchors)
    except TypeError:
        raise ValueError(f'fixed_anchors must be anchor indices, got {fixed_anchors!r}') \
            from None
    if any(not 0 <= j < m for j in fixed) or len(set(fixed)) != len(fixed):
        raise ValueError(f'fixed_anchors must be distinct indices in 0-{m - 1}, got '
                         f'{list(fixed)}')
    return tuple(sorted(fixed))


class _Problem:
    """
    The joint least squares: its parameters, residuals, Jacobian blocks and loss.

    Shared parameters ``x = x0 + basis @ q``: the free anchors' coordinates, then the tag
    offsets, then the anchor offsets; ``basis`` leaves out the gauge directions.
    """

    def __init__(self, model, ranges, tag_ranges, fixed, sigma, tag_sigma, mixture):
        self.model = model
        p, m = model.n_sections, model.n_anchors
        self.p, self.m = p, m
        self.free = np.array([j for j in range(m) if j not in fixed], dtype=int)
        self.fixed = fixed
        n_anchor = 3 * self.free.size
        self.n_x = n_anchor + p + m
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
        self.sigma = np.r_[np.full(p * m, sigma), np.full(self.near.size, tag_sigma)]
        self.loss = mixture.bind(self.sigma)     # called on (frames, rows)
        # d(range)/d(offsets): tag k and anchor j for a link, both tags for a tag-tag range.
        rows = self.sigma.size
        self.offset_rows = np.zeros((rows, p + m))
        self.offset_rows[np.arange(p * m), self.link_tag] = 1.0
        self.offset_rows[np.arange(p * m), p + self.link_anchor] = 1.0
        self.offset_rows[p * m + np.arange(self.near.size), self.near] += 1.0
        self.offset_rows[p * m + np.arange(self.near.size), self.far] += 1.0
        self.anchor_column = np.full(m, -1)
        self.anchor_column[self.free] = 3 * np.arange(self.free.size)
        self.x0 = np.r_[model.anchors[self.free].ravel(), model.tag_offsets,
                        model.anchor_offsets]
        self.basis, self.gauge = self._gauges(model, tag_ranges is not None
                                              and np.isfinite(tag_ranges).any())
        split = self.x0[n_anchor:n_anchor + p].sum() - self.x0[n_anchor + p:].sum()
        if tag_ranges is None or not np.isfinite(tag_ranges).any():
            self.x0[n_anchor:n_anchor + p] -= split / (p + m)       # onto the gauge
            self.x0[n_anchor + p:] += split / (p + m)

    def _gauges(self, model, tag_tag):
        """Return the basis (n_x, n_q) of the shared parameters' changes, and its story."""
        p, m = self.p, self.m
        blocks, story = [], []
        axis_distance = np.linalg.norm(model.anchors[:, :2] - model.base[:2], axis=1)
        pinned = None
        if not any(axis_distance[j] > ANCHOR_SEPARATION for j in self.fixed):
            off_axis = [j for j in self.free if axis_distance[j] > ANCHOR_SEPARATION]
            pinned = off_axis[0]
            story.append(f'anchor {pinned} keeps its configured bearing about the slew axis '
                         '(no fixed anchor off the axis defines the x direction of the truck)')
        for j in self.free:
            if j == pinned:
                radial = np.r_[model.anchors[j, :2] - model.base[:2], 0.0]
                blocks.append(np.c_[radial / np.linalg.norm(radial), [0.0, 0.0, 1.0]])
            else:
                blocks.append(np.eye(3))
        if tag_tag:
            blocks.append(np.eye(p + m))
            story.append('the tag-tag ranges split the link offsets between tags and anchors')
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
        return anchors, x[n_anchor:n_anchor + self.p], x[n_anchor + self.p:]

    def calibrated(self, q):
        """Return the model with the anchors and offsets of ``q``."""
        anchors, tag_offsets, anchor_offsets = self.unpack(self.x0 + self.basis @ q)
        return self.model.with_calibration(anchors, anchor_offsets, tag_offsets)

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
        anchors, tag_offsets, anchor_offsets = self.unpack(x)
        joints = self.model.forward_kinematics(psi[:, 0], psi[:, 1:])      # (n, p, 3)
        vectors = np.concatenate([joints[:, self.link_tag] - anchors[self.link_anchor],
                                  joints[:, self.near] - joints[:, self.far]], axis=1)
        distances = np.linalg.norm(vectors, axis=-1)
        offsets = self.offset_rows @ np.r_[tag_offsets, anchor_offsets]
        measured = self.measured[frames]
        mask = self.mask[frames]
        scaled = np.where(mask, (distances + offsets - np.nan_to_num(measured)) / self.sigma,
                          0.0)
        if not jacobian:
            return scaled, None, None
        units = vectors / np.maximum(distances, 1e-12)[..., None]
        moved = np.stack([self.model.joint_jacobian(s[0], s[1:]) for s in psi])  # (n,p,3,p+1)
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
        shared[:, :, 3 * self.free.size:] = self.offset_rows
        weight = mask / self.sigma
        return (scaled, angle * weight[..., None],
                (shared * weight[..., None]) @ self.basis)

    def robust(self, scaled, mask):
        """
        Return the NLOS-mixture cost (n,), its slope, IRLS weights and NLOS probabilities.

        Ranges follow the chain's mixture on their excess ``-scaled``; the weights are the
        chain's (``ChainMethod.loss``).
        """
        cost, excess_slope, nlos = self.loss(-scaled)
        cost, slope = np.where(mask, cost, 0.0), np.where(mask, -excess_slope, 0.0)
        weights = np.ones_like(scaled)
        large = np.abs(scaled) > 1.0
        weights[large] = np.clip(slope[large] / scaled[large], 1e-3, 1.0)
        return cost.sum(axis=1), slope, np.where(mask, weights, 0.0), np.where(mask, nlos, 0.0)


def _normal_blocks(angle, shared, slope, weights):
    """Return the block-arrow normal equations: U (n, a, a), W (n, a, q), V, g_a, g_q."""
    weighted = angle * weights[..., None]
    blocks = np.einsum('nla,nlb->nab', weighted, angle)
    coupling = np.einsum('nla,nlq->naq', weighted, shared)
    shared_block = np.einsum('nlq,nlr->qr', shared * weights[..., None], shared)
    return (blocks, coupling, shared_block, np.einsum('nla,nl->na', angle, slope),
            np.einsum('nlq,nl->q', shared, slope))


def _schur(blocks, coupling, shared_block):
    """Return the shared parameters' information with the angles eliminated, and U^-1."""
    inverse = np.linalg.inv(blocks)
    reduced = shared_block - np.einsum('naq,nab,nbr->qr', coupling, inverse, coupling)
    return 0.5 * (reduced + reduced.T), inverse


def _step(normal, damping):
    """Return the Levenberg–Marquardt step (angles (n, a), shared (q,)) for ``damping``."""
    blocks, coupling, shared_block, gradient_a, gradient_q = normal
    size = blocks.shape[1]
    diagonal = np.einsum('nii->ni', blocks)
    damped = blocks + (damping * (diagonal + 1e-9))[:, :, None] * np.eye(size)
    shared_damped = shared_block + damping * np.diag(np.diag(shared_block) + 1e-9)
    reduced, inverse = _schur(damped, coupling, shared_damped)
    right = gradient_q - np.einsum('naq,nab,nb->q', coupling, inverse, gradient_a)
    step_q = -np.linalg.solve(reduced, right)
    step_a = -np.einsum('nab,nb->na', inverse, gradient_a + coupling @ step_q)
    return step_a, step_q


def _least_squares(problem, psi, q, frames, max_iter, tol):
    """Levenberg–Marquardt on the NLOS loss from ``psi`` (n, p + 1), ``q``; as chain.fit."""
    mask = problem.mask[frames]

    def state(psi, q):
        scaled, angle, shared = problem.evaluate(psi, problem.x0 + problem.basis @ q, frames)
        cost, slope, weights, _ = problem.robust(scaled, mask)
        return float(cost.sum()), (angle, shared, slope, weights)

    cost, parts = state(psi, q)
    damping, iterations, converged = 1e-6, 0, False
    while iterations < max_iter:
        iterations += 1
        normal = _normal_blocks(*parts)
        while True:
            step_a, step_q = _step(normal, damping)
            trial_psi, trial_q = psi + step_a, q + step_q
            trial_cost, trial_parts = state(trial_psi, trial_q)
            if trial_cost <= cost or damping > 1e10:
                break
            damping *= 4.0
        if trial_cost > cost:
            converged = True
            break
        stalled = cost - trial_cost <= 1e-10 * max(abs(trial_cost), 1e-300)
        largest = max(np.max(np.abs(step_a)), np.max(np.abs(step_q), initial=0.0))
        psi, q, cost, parts = trial_psi, trial_q, trial_cost, trial_parts
        damping = max(damping / 3.0, 1e-9)
        if stalled or largest <= tol:
            converged = True
            break
    return psi, q, cost, iterations, converged


def _solve(chain, model, ranges, tag_ranges, frame, prior, warm):
    """Return chain's (joints, info) of one frame of the recording, None when unsolved."""
    measurements, _ = Measurements.clean(
        model, ranges[frame], None if tag_ranges is None else tag_ranges[frame])
    if not chain.enough_information(measurements):
        return None
    for _ in range(6):          # an exhausted search goes on where it stopped
        try:
            return chain.solve(measurements, prior, warm=warm)
        except SearchExhausted:
            continue
    return None


def _propagate(chain, model, ranges, tag_ranges, frames, first):
    """
    Return the angles (n, p + 1) of ``frames`` by chain, each warm from the last.

    ``first`` (p + 1,): the first frame's starting angles; NaN rows: unsolved.
    """
    psi = np.full((frames.size, model.n_sections + 1), np.nan)
    previous = model.forward_kinematics(first[0], first[1:])
    for index, frame in enumerate(frames):
        solved = _solve(chain, model, ranges, tag_ranges, frame, previous, True)
        if solved is not None:
            previous = solved[0]
            psi[index] = np.r_[solved[1]['slew'], solved[1]['pitches']]
    return psi


def _hypotheses(chain, model, ranges, tag_ranges, frame, most):
    """
    Return distinct postures (p + 1,) that fit the frame about as well, best first.

    A configuration that is off can make a wrong fold fit a frame best, and the warm
    start then follows it through the recording: each of these starts one recording.
    """
    solved = _solve(chain, model, ranges, tag_ranges, frame, None, False)
    if solved is None:
        return []
    joints, info = solved
    measurements, _ = Measurements.clean(
        model, ranges[frame], None if tag_ranges is None else tag_ranges[frame])
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


def _select(problem, chain, model, ranges, tag_ranges, usable, hypotheses, max_iter, tol):
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

    """
    stride = max(1, usable.size // SELECTION_FRAMES)
    subsample = usable[::stride]
    best, rms_before = None, float('nan')
    for number, hypothesis in enumerate(hypotheses):
        psi = _propagate(chain, model, ranges, tag_ranges, subsample, hypothesis)
        solved = np.all(np.isfinite(psi), axis=1)
        if not solved.any():
            continue
        frames, psi = subsample[solved], psi[solved]
        if number == 0:
            rms_before = _range_rms(problem, psi, problem.x0, frames)
        psi, q, cost, _, _ = _least_squares(problem, psi, np.zeros(problem.basis.shape[1]),
                                            frames, max_iter, tol)
        score = cost / problem.mask[frames].sum()
        if best is None or score < best[0]:
            best = (score, psi[0], q)
    if best is None:
        raise ValueError('no frame of the recording could be solved: nothing to calibrate')
    return best[1], best[2], rms_before


def _range_rms(problem, psi, x, frames):
    """Return the RMS of measured less predicted tag-anchor ranges of ``frames``, metres."""
    scaled = problem.evaluate(psi, x, frames, jacobian=False)[0][:, :problem.n_links]
    mask = problem.mask[frames, :problem.n_links]
    return float(np.sqrt(np.mean((scaled[mask] * problem.sigma[0]) ** 2))) if mask.any() \
        else float('nan')


def _covariance(information, scale):
    """Return ``scale^2 information^-1`` (inf along null directions) and the condition."""
    diagonal = np.sqrt(np.maximum(np.diag(information), 1e-300))
    normalised = information / np.outer(diagonal, diagonal)
    values, vectors = np.linalg.eigh(normalised)
    condition = float(values[-1] / values[0]) if values[0] > 0 else float('inf')
    null = values <= 1e-12 * values[-1]
    inverse = (vectors[:, ~null] / values[~null]) @ vectors[:, ~null].T
    covariance = scale ** 2 * inverse / np.outer(diagonal, diagonal)
    if null.any():      # what a null direction touches is undetermined
        touched = np.abs(vectors[:, null]).max(axis=1) > 1e-6
        covariance[touched, :] = np.inf
        covariance[:, touched] = np.inf
    return covariance, condition


def _motion_advice(direction):
    """Return which motion would locate an anchor along ``direction`` (3,) better."""
    if abs(direction[2]) > 0.7:
        return 'raise and lower the boom (luff) through a wider range'
    return 'slew the boom through a wider sweep'


def _verdict(problem, covariance, condition, anchor_tolerance, offset_tolerance):
    """Return the poorly determined parameters' names and the advice for each."""
    poorly, advice = [], []
    for index, j in enumerate(problem.free):
        block = covariance[3 * index:3 * index + 3, 3 * index:3 * index + 3]
        if not np.all(np.isfinite(block)):
            poorly.append(f'anchor {j}')
            advice.append(f'anchor {j} is not located at all: slew and luff the boom')
            continue
        values, vectors = np.linalg.eigh(block)
        if np.sqrt(max(values[-1], 0.0)) > anchor_tolerance:
            direction = vectors[:, -1] * np.sign(vectors[np.argmax(np.abs(vectors[:, -1])), -1])
            poorly.append(f'anchor {j}')
            advice.append(f'anchor {j} is located to +-{np.sqrt(values[-1]):.3g} m along '
                          f'({direction[0]:.2f}, {direction[1]:.2f}, {direction[2]:.2f}): '
                          f'{_motion_advice(direction)}')
    link_std = _link_std(problem, covariance)
    poor = link_std > offset_tolerance
    for k in np.flatnonzero(poor.all(axis=1)):      # a tag whose every link is uncertain
        poorly.append(f'link offsets of tag {k}')
        advice.append(f'the link offsets of tag {k} are known to +-{link_std[k].min():.3g} '
                      f'to {link_std[k].max():.3g} m: luff section {k + 1} through a wider '
                      f'range (the offset of its tag looks like a move along the line of sight)')
    poor[poor.all(axis=1)] = False
    for j in np.flatnonzero(poor.any(axis=0)):
        poorly.append(f'link offsets of anchor {j}')
        advice.append(f'the link offsets of anchor {j} are known to '
                      f'+-{link_std[poor[:, j], j].max():.3g} m: move the boom nearer to and '
                      f'farther from anchor {j} (slew and luff)')
    if condition > CONDITION_LIMIT and not poorly:
        poorly.append('the recording')
        advice.append(f'the parameters are nearly confounded (condition number '
                      f'{condition:.3g}): the boom hardly moved; slew and luff it')
    return poorly, advice


def _link_std(problem, covariance):
    """Return the standard deviation (p, m) of each link offset, metres."""
    n_anchor = 3 * problem.free.size
    p, m = problem.p, problem.m
    offsets = covariance[n_anchor:, n_anchor:]
    tags, anchors = np.meshgrid(np.arange(p), p + np.arange(m), indexing='ij')
    with np.errstate(invalid='ignore'):
        variance = (offsets[tags, tags] + offsets[anchors, anchors]
                    + 2 * offsets[tags, anchors])
    return np.sqrt(np.where(np.isnan(variance), np.inf, np.maximum(variance, 0.0)))


def _chain(model, sigma, tag_sigma, nlos_fraction, nlos_gamma):
    """Return the chain estimator that starts the frames' angles."""
    return ChainMethod(model, sigma=sigma, tag_sigma=tag_sigma, nlos_fraction=nlos_fraction,
                       nlos_gamma=nlos_gamma)


def calibrate(model, ranges, *, tag_ranges=None, fixed_anchors=(0,), sigma=0.1,
              tag_sigma=None, nlos_fraction=0.1, nlos_gamma=1.0, start=None, max_iter=100,
              tol=1e-10, refits=2, hypotheses=4, anchor_tolerance=ANCHOR_TOLERANCE,
              offset_tolerance=OFFSET_TOLERANCE):
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
    tag_ranges : array_like, shape (N, p, p), optional
        Tag-tag ranges, metres, NaN where missing; they also split the link offsets
        between tags and anchors (the gauge, see the module's description).
    fixed_anchors : sequence of int
        Anchors on the truck body (turret, cab) whose configured positions, with the
        boom's base and slew axis, define the truck frame; the others are fitted.
    sigma : float
        Range standard deviation, metres; ``tag_sigma`` (None: ``sigma``) the tag-tag one.
    tag_sigma : float, optional
        Tag-tag range standard deviation, metres.
    nlos_fraction, nlos_gamma : float
        The NLOS mixture (prior blocked fraction, mean excess in metres) the ranges are
        fitted under, as the chain estimator's; ``nlos_fraction=0``: plain least squares.
    start : array_like, shape (N, p + 1), optional
        Each frame's starting angles (slew, pitches), radians, NaN rows skipped; default:
        chain fits of each frame, warm-started from the previous one, from the best of
        ``hypotheses`` starts (below).
    max_iter : int
        Levenberg–Marquardt iterations per solve.
    tol : float
        Stop when no parameter moves more than this (radians or metres).
    hypotheses : int
        Most postures of the first frame tried as the recording's start: with the
        configuration off, a wrong fold can fit a frame best (and chain then follows it);
        each is fitted on a subsample, and the best fit starts the whole recording.
    refits : int
        Rounds in which frames the joint fit leaves far off (a chain start at a wrong
        fold) are solved again by chain with the calibrated model, and the joint fit
        repeated.
    anchor_tolerance, offset_tolerance : float
        Metres: anchors (std along their worst direction) and link offsets (std) less
        certain than these are reported as poorly determined.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ValueError
        On a wrong shape, bad fixed anchors, or a recording without a usable frame.

    """
    began = time.perf_counter()
    p, m = model.n_sections, model.n_anchors
    count = len(ranges) if np.ndim(ranges) == 3 else 0
    ranges = _finite_ranges(ranges, (count, p, m), 'ranges')
    if tag_ranges is not None:
        tag_ranges = _finite_ranges(tag_ranges, (count, p, p), 'tag_ranges')
        tag_ranges[:, np.arange(p), np.arange(p)] = np.nan
    fixed = _fixed_indices(fixed_anchors, m)
    tag_sigma = sigma if tag_sigma is None else tag_sigma
    chain = _chain(model, sigma, tag_sigma, nlos_fraction, nlos_gamma)
    mixture = NlosMixture(float(nlos_fraction), float(nlos_gamma))
    problem = _Problem(model, ranges, tag_ranges, fixed, float(sigma), float(tag_sigma),
                       mixture)
    q = np.zeros(problem.basis.shape[1])
    enough = problem.mask[:, :p * m].sum(axis=1) >= p + 1
    if start is None:
        usable, starts = np.flatnonzero(enough), []
        for frame in usable[:10]:       # the first frame chain can solve
            starts = _hypotheses(chain, model, ranges, tag_ranges, frame, hypotheses)
            if starts:
                usable = usable[usable >= frame]
                break
        first, q, rms_before = _select(problem, chain, model, ranges, tag_ranges, usable,
                                       starts, max_iter, tol)
        started = problem.calibrated(q)
        psi_all = np.full((count, p + 1), np.nan)
        psi_all[usable] = _propagate(_chain(started, sigma, tag_sigma, nlos_fraction,
                                            nlos_gamma), started, ranges, tag_ranges, usable,
                                     first)
    else:
        psi_all = _angles(start, (count, p + 1))
    frames = np.flatnonzero(np.all(np.isfinite(psi_all), axis=1) & enough)
    if frames.size == 0:
        raise ValueError('no frame of the recording could be solved: nothing to calibrate')
    if start is not None:
        rms_before = _range_rms(problem, psi_all[frames], problem.x0, frames)
    psi = psi_all[frames]
    total = 0
    for round_ in range(refits + 1):
        psi, q, _, iterations, converged = _least_squares(problem, psi, q, frames, max_iter,
                                                          tol)
        total += iterations
        if round_ == refits:
            break
        x = problem.x0 + problem.basis @ q
        scaled = problem.evaluate(psi, x, frames, jacobian=False)[0]
        cost = problem.robust(scaled, problem.mask[frames])[0]
        per_link = cost / np.maximum(problem.mask[frames].sum(axis=1), 1)
        lost = np.flatnonzero(per_link > max(12.5, 5 * np.median(per_link)))
        if lost.size == 0:
            break
        calibrated = problem.calibrated(q)
        refit = _chain(calibrated, sigma, tag_sigma, nlos_fraction, nlos_gamma)
        for index in lost:
            solved = _solve(refit, calibrated, ranges, tag_ranges, frames[index], None, False)
            if solved is not None:
                psi[index] = np.r_[solved[1]['slew'], solved[1]['pitches']]
    x = problem.x0 + problem.basis @ q
    anchors, tag_offsets, anchor_offsets = problem.unpack(x)
    scaled, angle, shared = problem.evaluate(psi, x, frames)
    mask = problem.mask[frames]
    _, slope, weights, nlos_links = problem.robust(scaled, mask)
    blocks, coupling, shared_block, _, _ = _normal_blocks(angle, shared, slope, weights)
    information = _schur(blocks + 1e-12 * np.eye(p + 1), coupling, shared_block)[0]
    dof = max(float(weights.sum()) - frames.size * (p + 1) - q.size, 1.0)
    residual_scale = float(np.sqrt(np.sum(weights * scaled ** 2) / dof))
    covariance_q, condition = _covariance(information, residual_scale)
    with np.errstate(invalid='ignore'):
        covariance = problem.basis @ np.nan_to_num(covariance_q, posinf=0.0) @ problem.basis.T
    undetermined = problem.basis[:, np.isinf(np.diag(covariance_q))].any(axis=1)
    covariance[undetermined, :] = np.inf
    covariance[:, undetermined] = np.inf
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    n_anchor = 3 * problem.free.size
    anchor_std = np.zeros((m, 3))
    anchor_std[problem.free] = std[:n_anchor].reshape(-1, 3)
    poorly, advice = _verdict(problem, covariance, condition, anchor_tolerance,
                              offset_tolerance)
    wandered = False
    try:
        calibrated = model.with_calibration(anchors, anchor_offsets, tag_offsets)
    except ValueError as exc:       # values no pump has: the recording did not pin them
        calibrated, wandered = model, True
        poorly = poorly + ['the recording']
        advice = advice + [f'the fit wandered to values no pump has ({exc}); record the '
                           'boom slewing and luffing every section']
    rms_after = _range_rms(problem, psi, x, frames)
    if wandered:
        status = 'poorly_excited'
        message = 'the recording does not determine everything: ' + '; '.join(advice)
    elif not converged:
        status = 'not_converged'
        message = (f'the joint fit did not converge in {max_iter} iterations: the result is '
                   'not to be used')
    elif poorly:
        status = 'poorly_excited'
        message = 'the recording does not determine everything: ' + '; '.join(advice)
    else:
        status = 'ok'
        message = (f'calibrated from {frames.size} frames: range RMS {rms_before:.3g} m -> '
                   f'{rms_after:.3g} m')
    postures = np.full((count, p + 1), np.nan)
    postures[frames] = psi
    nlos = np.zeros((count, p, m))
    nlos[frames] = nlos_links[:, :p * m].reshape(-1, p, m)
    used = np.zeros(count, bool)
    used[frames] = True
    return CalibrationResult(
        status=status, message=message, model=calibrated, anchors=anchors,
        anchor_offsets=anchor_offsets, tag_offsets=tag_offsets,
        link_offsets=tag_offsets[:, None] + anchor_offsets[None, :], anchor_std=anchor_std,
        anchor_offset_std=std[n_anchor + p:], tag_offset_std=std[n_anchor:n_anchor + p],
        link_offset_std=_link_std(problem, covariance), rms_before=rms_before,
        rms_after=rms_after, residual_scale=residual_scale, condition=condition,
        poorly_determined=poorly, gauge=problem.gauge, converged=converged,
        iterations=total, frames_used=used, postures=postures, nlos=nlos,
        covariance=covariance, seconds=time.perf_counter() - began)
