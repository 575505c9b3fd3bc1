"""How healthy an estimate is: the estimator's diagnostics as a level and key values.

Shared by the estimator node (``/diagnostics``) and the tools that print or record it.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ['OK', 'WARN', 'ERROR', 'Thresholds', 'assess']

OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class Thresholds:
    """Limits of a good estimate (metres)."""

    arm_length_warn: float = 0.05     #: worst section-length error for WARN
    arm_length_error: float = 0.5     #: ... for ERROR
    residual_warn: float = 0.5        #: range residual RMS for WARN
    residual_error: float = 2.0       #: ... for ERROR


def assess(diagnostics, thresholds, lengths):
    """Level, message and values of one frame's ``PostureEstimator.last_diagnostics``.

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
    values : dict of str -> str
    """
    estimated = np.asarray(diagnostics.get('section_lengths', np.full(len(lengths), np.nan)))
    length_error = np.abs(estimated - lengths)
    worst = float(np.nanmax(length_error)) if np.isfinite(length_error).any() else np.inf
    residual = float(diagnostics.get('range_residual_rms', np.nan))
    if diagnostics.get('method') == 'epp1':
        worst = 0.0                 # EPP1 does not model the lengths: not judged on them
    if not diagnostics.get('valid', False):
        level, message = ERROR, f'no estimate: {diagnostics.get("status", "unknown")}'
    elif not diagnostics.get('converged', True):
        level, message = WARN, 'solver stopped before converging'
    elif worst > thresholds.arm_length_error or residual > thresholds.residual_error:
        level, message = ERROR, f'poor fit: arm length error {worst:.3f} m, ' \
                                f'range residual {residual:.3f} m'
    elif worst > thresholds.arm_length_warn or residual > thresholds.residual_warn:
        level, message = WARN, f'weak fit: arm length error {worst:.3f} m, ' \
                               f'range residual {residual:.3f} m'
    else:
        level, message = OK, 'tracking'
    values = {'method': diagnostics.get('method', ''), 'status': diagnostics.get('status', ''),
              'range residual RMS [m]': f'{residual:.4f}',
              'missing links': str(diagnostics.get('missing_links', '')),
              'iterations': str(diagnostics.get('iterations', '')),
              'solve time [ms]': f'{1e3 * diagnostics.get("solve_time", np.nan):.2f}'}
    if 'predicted_rmse' in diagnostics:              # the chain's own uncertainty
        values['predicted RMSE [m]'] = f'{diagnostics["predicted_rmse"]:.4f}'
        for k, std in enumerate(diagnostics['joint_std'], start=1):
            values[f'joint {k} predicted std [m]'] = f'{std:.4f}'
    if 'nlos_links' in diagnostics:
        values['NLOS links'] = str(int(np.sum(diagnostics['nlos_links'])))
    for k, (estimate, configured, error) in enumerate(zip(estimated, lengths, length_error),
                                                    start=1):
        values[f'section {k} length [m]'] = f'{estimate:.4f}'
        values[f'section {k} configured [m]'] = f'{configured:.4f}'
        values[f'section {k} abs error [m]'] = f'{error:.4f}'
    return level, message, values
