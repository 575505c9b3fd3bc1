"""How healthy an estimate is: the estimator's diagnostics as a level and key values.

Shared by the estimator node (``/diagnostics``) and the tools that print or record it.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ['OK', 'WARN', 'ERROR', 'Thresholds', 'grade', 'report', 'assess']

OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class Thresholds:
    """Limits of a good estimate (metres)."""

    arm_length_warn: float = 0.05     #: worst section-length error for WARN
    arm_length_error: float = 0.5     #: ... for ERROR
    residual_warn: float = 0.5        #: range residual RMS for WARN
    residual_error: float = 2.0       #: ... for ERROR


def grade(diagnostics, thresholds, lengths):
    """Level and message of one frame's ``PostureEstimator.last_diagnostics``.

    Cheap enough for every frame (no formatting of the values).

    Parameters
    ----------
    diagnostics : dict
    thresholds : Thresholds
    lengths : ndarray, shape (p,)
        Configured section lengths, metres.

    Returns
    -------
    level : int
        OK, WARN or ERROR.
    message : str
    """
    if not diagnostics.get('valid', False):
        return ERROR, f'no estimate: {diagnostics.get("status", "unknown")}'
    if not diagnostics.get('converged', True):
        return WARN, 'solver stopped before converging'
    error = np.abs(np.asarray(diagnostics['section_lengths']) - lengths)
    # EPP1 does not model the lengths: it is not judged on them.
    worst = 0.0 if diagnostics.get('method') == 'epp1' else float(np.max(error))
    residual = float(diagnostics.get('range_residual_rms', np.nan))
    fit = f'arm length error {worst:.3f} m, range residual {residual:.3f} m'
    if worst > thresholds.arm_length_error or residual > thresholds.residual_error:
        return ERROR, f'poor fit: {fit}'
    if worst > thresholds.arm_length_warn or residual > thresholds.residual_warn:
        return WARN, f'weak fit: {fit}'
    return OK, 'tracking'


def report(diagnostics, lengths):
    """The key values of one frame's diagnostics, as text for ``/diagnostics``."""
    estimated = np.asarray(diagnostics.get('section_lengths', np.full(len(lengths), np.nan)))
    values = {'method': diagnostics.get('method', ''), 'status': diagnostics.get('status', ''),
              'range residual RMS [m]': f'{diagnostics.get("range_residual_rms", np.nan):.4f}',
              'missing links': str(diagnostics.get('missing_links', '')),
              'iterations': str(diagnostics.get('iterations', '')),
              'solve time [ms]': f'{1e3 * diagnostics.get("solve_time", np.nan):.2f}'}
    if 'predicted_rmse' in diagnostics:              # the chain's own uncertainty
        values['predicted RMSE [m]'] = f'{diagnostics["predicted_rmse"]:.4f}'
        for k, std in enumerate(diagnostics['joint_std'], start=1):
            values[f'joint {k} predicted std [m]'] = f'{std:.4f}'
    if 'nlos_links' in diagnostics:
        values['NLOS links'] = str(int(np.sum(diagnostics['nlos_links'])))
    for k, (estimate, configured) in enumerate(zip(estimated, lengths), start=1):
        values[f'section {k} length [m]'] = f'{estimate:.4f}'
        values[f'section {k} configured [m]'] = f'{configured:.4f}'
        values[f'section {k} abs error [m]'] = f'{abs(estimate - configured):.4f}'
    return values


def assess(diagnostics, thresholds, lengths):
    """:func:`grade` and :func:`report` together: (level, message, values)."""
    return (*grade(diagnostics, thresholds, lengths), report(diagnostics, lengths))
