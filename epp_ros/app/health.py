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
How healthy an estimate is: the estimator's diagnostics as a level and key values.

Shared by the estimator node (``/diagnostics``) and the tools that print, record or read
it back (:func:`nlos_pairs`, :func:`joint_stds`): the one home of those values' keys.
"""
from epp_ros.core.estimation import ERROR, OK, Thresholds, WARN
import numpy as np

__all__ = ['OK', 'WARN', 'ERROR', 'Thresholds', 'grade', 'report', 'assess',
           'nlos_text', 'nlos_pairs', 'joint_stds', 'NLOS_FLAGGED']

#: Key of the links judged NLOS (:func:`nlos_text`).
NLOS_FLAGGED = 'NLOS flagged links'


def _joint_std_key(k, tracked):
    """Key of joint k's (1-based) standard deviation: a motion model's, or the bound's."""
    return f'joint {k} {"tracked" if tracked else "predicted"} std [m]'


def grade(diagnostics):
    """
    Level and message of one frame's ``PostureEstimator.last_diagnostics``.

    The level is the integrity verdict's (``core.integrity``: thresholds, consistency,
    observability), raised to WARN when the solver stopped before converging. Cheap
    enough for every frame.

    Returns
    -------
    level : int
        OK, WARN or ERROR; a frame at ERROR was not published.
    message : str

    """
    if not diagnostics.valid:
        detail = diagnostics.message
        shown = detail and not detail.startswith('no estimate')
        return ERROR, f'no estimate: {diagnostics.status}' + (f' ({detail})' if shown else '')
    level, message = diagnostics.level, diagnostics.message
    if diagnostics.converged is False:
        return max(level, WARN), 'solver stopped before converging'
    return level, message


def nlos_text(nlos_links):
    """
    Name the links judged NLOS: ``'2:3 5:1'`` is joint 2 to anchor 3 and joint 5 to anchor 1.

    Parameters
    ----------
    nlos_links : array_like of bool, shape (p, m)
        ``last_diagnostics.nlos_links``: row k is the tag of joint k + 1, column j anchor
        j + 1.

    Returns
    -------
    str
        ``joint:anchor`` pairs, 1-based, joint-major, separated by spaces; empty when none.

    """
    blocked = np.asarray(nlos_links)
    if blocked.ndim != 2:
        return ''
    return ' '.join(f'{k + 1}:{j + 1}' for k, j in np.argwhere(blocked))


def nlos_pairs(text):
    """
    Read :func:`nlos_text` back: ``'2:3 5:1'`` -> [(2, 3), (5, 1)].

    The pairs are (joint, anchor), 1-based; what is not a pair of numbers is left out.
    """
    pairs = []
    for word in (text or '').split():
        joint, _, anchor = word.partition(':')
        if joint.isdigit() and anchor.isdigit():
            pairs.append((int(joint), int(anchor)))
    return pairs


def joint_stds(values, joints):
    """
    Each joint's standard deviation from the values of :func:`report`, metres.

    A motion model's own (``tracked``) where the method has one, else the Cramér–Rao
    bound at the estimate, widened by the residuals' variance factor (``predicted``); NaN
    where neither is given.

    Parameters
    ----------
    values : dict of str
        The key values of a ``/diagnostics`` status.
    joints : int
        Joints of the boom, p.

    Returns
    -------
    list of float, length p

    """
    stds = []
    for k in range(1, joints + 1):
        text = values.get(_joint_std_key(k, True), values.get(_joint_std_key(k, False), 'nan'))
        try:
            stds.append(float(text))
        except ValueError:
            stds.append(float('nan'))
    return stds


def _or_nan(value):
    return np.nan if value is None else value


def _or_blank(value):
    return '' if value is None else str(value)


def _noise_values(diagnostics):
    """Return the range noise in use and the common bias taken off, as text."""
    values = {}
    noise = diagnostics.noise
    if noise is not None:                   # learned while running, or as told
        values['range sigma [m]'] = f'{noise.sigma:.4f}'
        values['range sigma per metre'] = f'{noise.eta:.5f}'
        values['NLOS fraction'] = f'{noise.nlos_fraction:.3f}'
        values['NLOS mean excess [m]'] = f'{noise.nlos_gamma:.3f}'
        values['outlier share'] = f'{noise.outliers:.4f}'
        values['noise learned from links'] = str(noise.links)
    if diagnostics.range_bias is not None:  # the common bias taken off the ranges
        offset, slope = diagnostics.range_bias
        values['range bias [m]'] = f'{offset:.4f}'
        values['range bias per metre'] = f'{slope:.5f}'
    return values


def report(diagnostics, lengths):
    """
    Return the key values of one frame's diagnostics, as text for ``/diagnostics``.

    Among them ``NLOS links``, how many links the integrity checks judged NLOS, and
    ``NLOS flagged links``, which (:func:`nlos_text`).
    """
    estimated = np.full(len(lengths), np.nan) if diagnostics.section_lengths is None \
        else np.asarray(diagnostics.section_lengths)
    values = {'method': diagnostics.method, 'status': diagnostics.status,
              'range residual RMS [m]': f'{_or_nan(diagnostics.range_residual_rms):.4f}',
              'missing links': _or_blank(diagnostics.missing_links),
              'iterations': _or_blank(diagnostics.iterations),
              'solve time [ms]': f'{1e3 * _or_nan(diagnostics.solve_time):.2f}'}
    if diagnostics.predicted_rmse is not None:        # the bound at the estimate, widened
        values['predicted RMSE [m]'] = f'{diagnostics.predicted_rmse:.4f}'
        for k, std in enumerate(diagnostics.joint_std, start=1):
            values[_joint_std_key(k, False)] = f'{std:.4f}'
    if 'posterior_joint_std' in diagnostics.details:  # a motion model's own uncertainty
        for k, std in enumerate(diagnostics.details['posterior_joint_std'], start=1):
            values[_joint_std_key(k, True)] = f'{std:.4f}'
    if 'hypotheses' in diagnostics.details:
        values['hypotheses'] = str(diagnostics.details['hypotheses'])
    values.update(_noise_values(diagnostics))
    for anchor, shift in (diagnostics.anchor_shifts or {}).items():   # seen, x y z
        values[f'anchor {anchor} shift [m]'] = '{:.3f} {:.3f} {:.3f}'.format(*shift)
    if diagnostics.noise_rmse is not None:            # the predicted RMSE without the common bias
        values['noise RMSE [m]'] = f'{diagnostics.noise_rmse:.4f}'
    if diagnostics.nlos_links is not None:
        blocked = np.asarray(diagnostics.nlos_links)
        values['NLOS links'] = str(int(np.sum(blocked)))
        values[NLOS_FLAGGED] = nlos_text(blocked)
    if diagnostics.outlier_links is not None:       # set aside as no noise explains them
        outlying = np.asarray(diagnostics.outlier_links)
        values['outlier links'] = str(int(np.sum(outlying)))
        values['outlier flagged links'] = nlos_text(outlying)
    if diagnostics.chi_square is not None:
        values['range chi-square'] = (f'{diagnostics.chi_square:.1f} (limit '
                                      f'{diagnostics.chi_square_limit:.1f})')
    if diagnostics.variance_factor is not None:     # > 1: the predicted stds were widened
        values['variance factor'] = f'{diagnostics.variance_factor:.2f}'
    if diagnostics.ambiguous_joints:
        values['ambiguous joints'] = ' '.join(map(str, diagnostics.ambiguous_joints))
    for k, (estimate, configured) in enumerate(zip(estimated, lengths), start=1):
        values[f'section {k} length [m]'] = f'{estimate:.4f}'
        values[f'section {k} configured [m]'] = f'{configured:.4f}'
        values[f'section {k} abs error [m]'] = f'{abs(estimate - configured):.4f}'
    return values


def assess(diagnostics, lengths):
    """:func:`grade` and :func:`report` together: (level, message, values)."""
    return (*grade(diagnostics), report(diagnostics, lengths))
