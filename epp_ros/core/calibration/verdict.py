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
What a calibration determines: its covariance, the verdict, and the advice on the motion.

``core.calibrate`` fits; this judges the fit: the covariance of the shared parameters from
their information (inf along what the recording does not determine), which anchors and
link offsets are known worse than their tolerances, which motion would determine them
better, whether the model fits every tag, anchor and link alike (and the likely cause
where it does not), and the status and message of the result.
"""
import numpy as np

__all__ = ['CONDITION_LIMIT', 'MISFIT_RATIO', 'MISFIT_Z', 'PLAUSIBLE_OFFSET',
           'scaled_covariance', 'poorly_determined', 'link_offset_std', 'common_offset_std',
           'implausible', 'misfit', 'verdict']

#: A tag's, an anchor's or a link's mean squared residual this many times the others' ...
MISFIT_RATIO = 1.3
#: ... and this many standard errors above them: the model does not fit it.
MISFIT_Z = 5.0

#: Metres: link offsets (antenna delays, real links' biases: +0.04 to +0.33 m at the 5th
#: and 95th percentiles) beyond this are a length absorbed, not a delay.
PLAUSIBLE_OFFSET = 0.6

#: Condition number (of the shared parameters' information, normalised to unit diagonal)
#: above which a recording is reported as poorly exciting, whatever its length.
CONDITION_LIMIT = 1e4


def scaled_covariance(information, scale):
    """Return ``scale^2 information^-1`` (inf along null directions) and the condition."""
    diagonal = np.diag(information)
    diagonal = np.where(diagonal > 0, np.sqrt(np.abs(diagonal)), 1.0)
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


def poorly_determined(problem, covariance, condition, anchor_tolerance, offset_tolerance):
    """
    Return the poorly determined parameters' names and the advice for each.

    ``problem``: the calibration's (its free anchors, ``p``, ``m``); ``covariance`` of its
    shared parameters (:func:`scaled_covariance`, mapped to the free anchors' xyz, the tag
    offsets and the anchor offsets); tolerances in metres.
    """
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
    for k in range(problem.p if problem.length_index.size else 0):
        std = np.sqrt(covariance[problem.length_index[k], problem.length_index[k]])
        if not std <= anchor_tolerance:
            poorly.append(f'arm length {k}')
            advice.append(f'the length of section {k + 1} is known to +-{std:.3g} m: luff it '
                          'through a wider range and slew (along the lines of sight a length '
                          "looks like its tag's offset)")
    link_std = link_offset_std(problem, covariance)
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


def _link_rows(problem, size):
    """Return the matrix (p m, size) from the offsets (tags, anchors, links' own) to links."""
    p, m = problem.p, problem.m
    rows = np.zeros((p * m, size))
    rows[np.arange(p * m), np.repeat(np.arange(p), m)] = 1.0
    rows[np.arange(p * m), p + np.tile(np.arange(m), p)] = 1.0
    if problem.n_pairs:
        rows[np.arange(p * m), p + m + np.arange(p * m)] = 1.0
    return rows


def _combined_variance(rows, covariance):
    """Return the variance of each row's combination of the parameters (inf: unknown)."""
    finite = np.isfinite(covariance).all(axis=0)
    variance = np.full(len(rows), np.inf)
    known = ~(rows[:, ~finite] != 0).any(axis=1)
    used = rows[np.ix_(known, finite)]
    variance[known] = np.einsum('li,ij,lj->l', used, covariance[np.ix_(finite, finite)], used)
    return np.maximum(variance, 0.0)


def link_offset_std(problem, covariance):
    """Return the standard deviation (p, m) of each link's offset, metres (inf: unknown)."""
    offsets = covariance[np.ix_(problem.offset_index, problem.offset_index)]
    rows = _link_rows(problem, offsets.shape[0])
    return np.sqrt(_combined_variance(rows, offsets)).reshape(problem.p, problem.m)


def common_offset_std(problem, covariance):
    """Return the standard deviation of the links' mean offset, metres (inf: unknown)."""
    offsets = covariance[np.ix_(problem.offset_index, problem.offset_index)]
    rows = _link_rows(problem, offsets.shape[0])
    return float(np.sqrt(_combined_variance(rows.mean(axis=0, keepdims=True), offsets)[0]))


def _mean_square(squares, expected):
    """Return ``squares / expected``, 0 where nothing is expected (no clear range)."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(expected > 0, squares / expected, 0.0)


def _worse(squares, expected, correlation):
    """
    Return how much worse each group fits than all (ratio of mean squares), and its z.

    ``squares``, ``expected``: the group's sum of squared scaled residuals and what a fit
    leaves of it; the z-score's spread counts ``correlation`` frames as one.
    """
    pooled = max(float(_mean_square(squares.sum(), expected.sum())), 1e-300)
    ratio = _mean_square(squares, expected) / pooled
    with np.errstate(divide='ignore', invalid='ignore'):
        z = np.where(expected > 0, (ratio - 1.0) / np.sqrt(2.0 * correlation / expected), 0.0)
    return ratio, z


def misfit(squares, expected, correlation):
    """
    Return the advice on what the calibrated model does not fit, and the likely cause.

    ``squares``, ``expected`` (p, m): each link's sum of squared scaled residuals and what
    a fit that explains the ranges leaves of it (its ranges' ``1 - leverage``);
    ``correlation``: the residuals' integrated autocorrelation time, frames. A tag, an
    anchor or a link whose residuals are :data:`MISFIT_RATIO` times the others' and
    :data:`MISFIT_Z` standard errors above them is named with its likely cause; a tag or
    an anchor only when more than one of its links makes it so.
    """
    advice, links = [], set()
    pooled = _mean_square(squares.sum(), expected.sum())
    for axis, kind, cause in ((1, 'tag', _tag_cause), (0, 'anchor', _anchor_cause)):
        ratio, z = _worse(squares.sum(axis=axis), expected.sum(axis=axis), correlation)
        for index in np.flatnonzero((ratio > MISFIT_RATIO) & (z > MISFIT_Z)):
            group = (index, slice(None)) if kind == 'tag' else (slice(None), index)
            worst = np.argmax(_mean_square(squares[group], expected[group]))
            rest = np.delete(np.arange(squares[group].size), worst)
            if _mean_square(squares[group][rest].sum(), expected[group][rest].sum()) \
                    > MISFIT_RATIO * pooled:
                advice.append(f'the ranges of {kind} {index} fit {ratio[index]:.2g} times '
                              f'worse than the others: {cause(index)}')
            else:
                links.add((index, worst) if kind == 'tag' else (worst, index))
    ratio, z = _worse(squares, expected, correlation)
    flagged = set(zip(*np.nonzero((ratio > MISFIT_RATIO) & (z > MISFIT_Z))))
    for k, j in sorted(links | (flagged if not advice else set())):
        advice.append(f'the link tag {k} - anchor {j} fits {ratio[k, j]:.2g} times worse '
                      'than the others: its bias varies (a path blocked for long, an '
                      'antenna that turns); check its mounting')
    return advice


def implausible(link_offsets):
    """
    Return the advice on tags whose links came out longer than UWB modules make them.

    ``link_offsets`` (p, m), metres. A tag whose every link offset is beyond
    :data:`PLAUSIBLE_OFFSET` (antenna delays and real links' biases stay well within it)
    has most likely absorbed a length: the section's, or the tag's place on the boom, seen
    along the lines of sight.
    """
    advice = []
    for k in np.flatnonzero(np.all(np.abs(link_offsets) > PLAUSIBLE_OFFSET, axis=1)):
        advice.append(f'the links of tag {k} came out {np.median(link_offsets[k]):+.2f} m '
                      f'long, more than UWB modules add: {_tag_cause(k)}')
    return advice


def _tag_cause(k):
    return (f'the length of section {k + 1} (arm_lengths[{k}]) or where tag {k} sits on the '
            'boom is likely wrong (fit_arm_lengths, epp_calibrate --fit-arm-lengths, fits the '
            'lengths), or the fit took a wrong fold of it')


def _anchor_cause(j):
    return (f'anchor {j} is likely not where the fit put it (a wrong start: check its '
            'configured position) or its antenna is blocked')


def verdict(wandered, converged, poorly, advice, max_iter, frames, rms_before, rms_after,
            misfits=()):
    """Return the status and the message of the verdict."""
    if not converged and not wandered:
        return 'not_converged', (f'the joint fit did not converge in {max_iter} iterations: '
                                 'the result is not to be used')
    if misfits and not wandered:
        return 'misfit', ('the calibrated model does not fit the recording, the result is '
                          'not to be used: ' + '; '.join(misfits))
    if poorly:
        return 'poorly_excited', ('the recording does not determine everything: '
                                  + '; '.join(advice))
    return 'ok', (f'calibrated from {frames.size} frames: range RMS {rms_before:.3g} m -> '
                  f'{rms_after:.3g} m')
