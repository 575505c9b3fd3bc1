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
SDP relaxation of range-only sensor localisation (Biswas-Ye).

P. Biswas and Y. Ye, "Semidefinite programming for ad hoc wireless sensor network
localization", IPSN 2004; P. Biswas, T.-C. Lian, T.-C. Wang and Y. Ye, "Semidefinite
programming based algorithms for sensor network localization", ACM TOSN 2(2), 2006.

Benchmark baseline only: it needs the optional ``cvxpy`` package (a benchmark extra),
which is imported when an :class:`SDPLocalizer` is built, never at package import.

With tag positions ``X = [x_1 ... x_p]`` (3 x p) and ``Y = X^T X``, every squared
anchor-tag distance ``||a_j - x_k||^2 = ||a_j||^2 - 2 a_j^T x_k + Y_kk`` is linear in
``(X, Y)``. Relaxing ``Y = X^T X`` to ``Y >= X^T X`` gives the semidefinite constraint

    Z = [[I_3, X], [X^T, Y]]  positive semidefinite,  size 3 + p,

and the estimate minimises the l1 misfit ``sum_kj w_kj |relaxed d_kj^2 - delta_kj^2|``
over the measured links (``w_kj = 1``; a missing link has ``w_kj = 0``). With noise-free
ranges and at least four non-coplanar anchors per tag the relaxation is tight and
recovers the positions exactly. No tag-tag terms are used: arm lengths are not imposed.
"""
import time
import warnings

import numpy as np

__all__ = ['SDPLocalizer']

_SOLVED = ('optimal', 'optimal_inaccurate')


class SDPLocalizer:
    """
    Biswas-Ye SDP localiser for ``n_tags`` tags ranged by fixed anchors.

    One parametrised (DPP) cvxpy problem is built here, so repeated :meth:`solve`
    calls only update parameter values and do not recompile it.

    Parameters
    ----------
    anchors : array_like, shape (m, 3)
        Anchor positions, metres.
    n_tags : int
        Number of tags p.
    solver : str, optional
        cvxpy solver name; the default Clarabel ships with cvxpy.

    Raises
    ------
    ImportError
        When cvxpy is not installed.

    """

    def __init__(self, anchors, n_tags, solver='CLARABEL'):
        try:
            import cvxpy as cp
        except ImportError as exc:
            raise ImportError(
                'the SDP baseline needs cvxpy: pip install cvxpy (a benchmark extra)') from exc
        anchors = np.asarray(anchors, dtype=float)
        if anchors.ndim != 2 or anchors.shape[1] != 3 or int(n_tags) < 1:
            raise ValueError('anchors must have shape (m, 3) and n_tags must be >= 1')
        self.anchors, self.n_tags, self.solver = anchors, int(n_tags), solver
        p, m = self.n_tags, len(anchors)
        # Distances are translation invariant: centring the anchors conditions the SDP.
        self._centre = anchors.mean(axis=0)
        local = anchors - self._centre
        self._weights = cp.Parameter((p, m), nonneg=True)
        self._target = cp.Parameter((p, m))       # w_kj * delta_kj^2
        z = cp.Variable((3 + p, 3 + p), PSD=True)
        self._x = z[:3, 3:]
        relaxed = (cp.reshape(cp.diag(z[3:, 3:]), (p, 1), order='C') @ np.ones((1, m))
                   - 2.0 * self._x.T @ local.T
                   + np.ones((p, 1)) @ np.sum(local ** 2, axis=1)[None, :])
        # w |d - delta^2| = |w d - w delta^2| for w >= 0; this form is DPP (w times
        # |d - delta^2| would multiply two parameter-dependent terms).
        objective = cp.sum(cp.abs(cp.multiply(self._weights, relaxed) - self._target))
        self._problem = cp.Problem(cp.Minimize(objective), [z[:3, :3] == np.eye(3)])

    def solve(self, ranges):
        """
        Estimate the tag positions from one frame of ranges.

        Parameters
        ----------
        ranges : array_like, shape (p, m)
            Range from tag k to anchor j, metres; NaN marks a missing link.

        Returns
        -------
        positions : ndarray, shape (p, 3)
            Estimated tag positions, metres (``X^T``).
        info : dict
            ``status`` (cvxpy status string), ``solve_time`` (wall-clock seconds of
            ``problem.solve``) and ``objective`` (weighted l1 misfit, square metres).

        Raises
        ------
        RuntimeError
            When the solver does not reach an (inaccurate) optimum.

        """
        ranges = np.asarray(ranges, dtype=float)
        if ranges.shape != self._weights.shape:
            raise ValueError(f'ranges must have shape {self._weights.shape}, got {ranges.shape}')
        measured = np.isfinite(ranges)
        weights = measured.astype(float)
        self._weights.value = weights
        self._target.value = weights * np.where(measured, ranges, 0.0) ** 2
        start = time.perf_counter()
        with warnings.catch_warnings():
            # Reported as status 'optimal_inaccurate' instead.
            warnings.filterwarnings('ignore', message='Solution may be inaccurate',
                                    category=UserWarning)
            self._problem.solve(solver=self.solver)
        elapsed = time.perf_counter() - start
        status = self._problem.status
        if status not in _SOLVED or self._x.value is None:
            raise RuntimeError(f'SDP solver {self.solver} failed: status {status}')
        info = {'status': status, 'solve_time': elapsed, 'objective': self._problem.value}
        return self._x.value.T + self._centre, info
