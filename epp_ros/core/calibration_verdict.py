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
better, and the status and message of the result.
"""
import numpy as np

__all__ = ['CONDITION_LIMIT', 'scaled_covariance', 'poorly_determined', 'link_offset_std',
           'verdict']

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


def link_offset_std(problem, covariance):
    """Return the standard deviation (p, m) of each link offset, metres."""
    n_anchor = 3 * problem.free.size
    p, m = problem.p, problem.m
    offsets = covariance[n_anchor:, n_anchor:]
    tags, anchors = np.meshgrid(np.arange(p), p + np.arange(m), indexing='ij')
    with np.errstate(invalid='ignore'):
        variance = (offsets[tags, tags] + offsets[anchors, anchors]
                    + 2 * offsets[tags, anchors])
    return np.sqrt(np.where(np.isnan(variance), np.inf, np.maximum(variance, 0.0)))


def verdict(wandered, converged, poorly, advice, max_iter, frames, rms_before, rms_after):
    """Return the status and the message of the verdict."""
    if not converged and not wandered:
        return 'not_converged', (f'the joint fit did not converge in {max_iter} iterations: '
                                 'the result is not to be used')
    if poorly:
        return 'poorly_excited', ('the recording does not determine everything: '
                                  + '; '.join(advice))
    return 'ok', (f'calibrated from {frames.size} frames: range RMS {rms_before:.3g} m -> '
                  f'{rms_after:.3g} m')
