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
The NLOS loss compiled: its formulas for one link, and tags' losses at candidate points.

``LinkLoss`` (``core.model.nlos``) is the reference; :func:`link_loss` repeats its
formulas for one range, from the constants :func:`loss_terms` collects, for the compiled
fit (``estimation.methods.compiled_chain``), and :func:`link_cost` its cost alone for
:func:`tag_losses`: a tag's ranges scored at each of many candidate positions (a joint's
other folds, the tip all round its hinge, a whole posture), which in numpy is a dozen
calls on arrays of a few hundred elements per candidate set (issue #30). The slope's
three exponentials are a third of a range's time, and the compiler does not drop them
when only the cost is read. :func:`link_floors`: the least a link's range can cost
(``LinkLoss.floor``), which rules out candidates no better placed joint could save.
Imported at first use only (``solvers.compiled``).
"""
from functools import lru_cache
import math

from epp_ros.core.solvers.compiled import compiled
import numpy as np

__all__ = ['link_cost', 'link_floors', 'link_loss', 'log_ndtr', 'loss_terms', 'tag_losses']

_SQRT1_2 = math.sqrt(0.5)
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_LOG_2 = math.log(2.0)
#: Rows of :func:`loss_terms`.
_TERMS = ('inverse_g', 'los_offset', 'blocked_offset', 'outlier_ratio', 'outlier_offset')


@lru_cache(maxsize=32)
def loss_terms(link_loss):
    """
    Return a ``LinkLoss``'s constants as one array: shape (7, n), or (0, 0).

    Rows: ``inverse_g``, ``los_offset``, ``blocked_offset``, ``outlier_ratio``,
    ``outlier_offset``, then the loss's value and slope at zero excess; one column per
    link (n its sigmas' size). A Gaussian loss has none.
    """
    if link_loss.gaussian:
        return np.zeros((0, 0))
    zero_cost, zero_slope = link_loss.at_zero
    return np.ascontiguousarray(np.vstack(
        [np.broadcast_to(getattr(link_loss, name), zero_cost.shape).ravel() for name in _TERMS]
        + [zero_cost.ravel(), zero_slope.ravel()]), dtype=float)


@compiled
def log_ndtr(z):
    """Return log Phi(z), as ``scipy.special.log_ndtr`` to rounding."""
    if z > -1.0:
        return math.log1p(-0.5 * math.erfc(z * _SQRT1_2))
    if z > -37.0:               # erfc stays a normal number
        return math.log(0.5 * math.erfc(-z * _SQRT1_2))
    inverse = 1.0 / (z * z)     # Mills' ratio's asymptotic series
    series = 1.0 + inverse * (-1.0 + inverse * (3.0 + inverse * (-15.0 + inverse * (
        105.0 + inverse * (-945.0 + inverse * 10395.0)))))
    return -0.5 * z * z - math.log(-z) - _HALF_LOG_2PI + math.log(series)


@compiled
def _logaddexp(x, y):
    """Return log(exp(x) + exp(y)), as ``numpy.logaddexp``."""
    if x == y:
        return x + _LOG_2
    difference = x - y
    if difference > 0:
        return x + math.log1p(math.exp(-difference))
    return y + math.log1p(math.exp(difference))


@compiled
def _log_total(s, terms, i):
    """Return the log of the mixture's density at excess ``s`` on link ``i``, z, log cdf(z)."""
    inverse_g, los_offset, blocked_offset = terms[0, i], terms[1, i], terms[2, i]
    outlier_ratio, outlier_offset = terms[3, i], terms[4, i]
    z = s - inverse_g
    log_cdf = log_ndtr(z)
    los = los_offset - 0.5 * s ** 2
    blocked = blocked_offset - inverse_g * s + log_cdf
    outlier = outlier_offset - 0.5 * (outlier_ratio * s) ** 2
    return _logaddexp(_logaddexp(los, blocked), outlier), los, blocked, outlier, z, log_cdf


@compiled
def link_cost(s, terms, i):
    """Return the cost of excess ``s`` on link ``i``: :func:`link_loss`'s, without its slope."""
    total = _log_total(s, terms, i)[0]
    return -total - terms[5, i] - terms[6, i] * s


@compiled
def link_loss(s, terms, i):
    """Return (cost, slope) of excess ``s`` on link ``i``: ``LinkLoss.__call__``'s formulas."""
    inverse_g, outlier_ratio = terms[0, i], terms[3, i]
    total, _, blocked, outlier, z, log_cdf = _log_total(s, terms, i)
    nlos, outlying = math.exp(blocked - total), math.exp(outlier - total)
    mills = math.exp(-0.5 * z ** 2 - _HALF_LOG_2PI - log_cdf)
    slope = ((1.0 - nlos - outlying) * s + nlos * (inverse_g - mills)
             + outlying * outlier_ratio ** 2 * s - terms[6, i])
    return -total - terms[5, i] - terms[6, i] * s, slope


@compiled
def _blocked_peak(a):
    """
    Return the most ``log Phi(t) - a t`` reaches over t, for ``a`` > 0.

    Where ``pdf(t) / cdf(t) = a``: Newton's method on the log of that ratio, concave and
    falling, lands right of the root from ``-a`` and then falls to it.
    """
    t = -a
    for _ in range(60):
        mills = math.exp(-0.5 * t * t - _HALF_LOG_2PI - log_ndtr(t))
        step = (math.log(mills) - math.log(a)) / (-t - mills)
        t -= step
        if abs(step) <= 1e-12 * (1.0 + abs(t)):
            break
    return log_ndtr(t) - a * t


@compiled
def link_floors(terms):
    """Return ``LinkLoss.floor`` of each column of :func:`loss_terms`, shape (n,)."""
    out = np.empty(terms.shape[1])
    for i in range(terms.shape[1]):
        inverse_g, los_offset, blocked_offset = terms[0, i], terms[1, i], terms[2, i]
        outlier_ratio, outlier_offset = terms[3, i], terms[4, i]
        zero_cost, zero_slope = terms[5, i], terms[6, i]
        a = inverse_g - zero_slope
        if a <= 0.0:                # never so (the slope at zero is <= 0): no floor
            out[i] = -math.inf
            continue
        los = los_offset + 0.5 * zero_slope ** 2
        blocked = blocked_offset - a * inverse_g + _blocked_peak(a)
        outlier = outlier_offset + 0.5 * (zero_slope / outlier_ratio) ** 2
        out[i] = -_logaddexp(_logaddexp(los, blocked), outlier) - zero_cost
    return out


@compiled
def tag_losses(points, tags, ranges, sigma, anchors, terms):
    """
    Return the loss of tag ``tags[i]``'s ranges were it at ``points[i]``, shape (n,).

    ``points`` (n, 3) metres; ``ranges`` and ``sigma`` (q, m), a missing range NaN (it
    scores 0); ``terms``: :func:`loss_terms` of a loss bound to one sigma (one column) or
    to each of the (q, m) links, or (0, 0) for the Gaussian ``excess**2 / 2``.
    """
    m = anchors.shape[0]
    out = np.zeros(points.shape[0])
    for i in range(points.shape[0]):
        k = tags[i]
        total = 0.0
        for j in range(m):
            measured = ranges[k, j]
            if not math.isfinite(measured):
                continue
            distance = math.sqrt((points[i, 0] - anchors[j, 0]) ** 2
                                 + (points[i, 1] - anchors[j, 1]) ** 2
                                 + (points[i, 2] - anchors[j, 2]) ** 2)
            s = (measured - distance) / sigma[k, j]
            if terms.shape[0] == 0:
                total += 0.5 * s * s
            else:
                total += link_cost(s, terms, k * m + j if terms.shape[1] > 1 else 0)
        out[i] = total
    return out


def compile_now():
    """Compile :func:`tag_losses` for both kinds of terms, and :func:`link_floors`."""
    points, tags = np.zeros((1, 3)), np.zeros(1, dtype=np.int64)
    ranges, sigma, anchors = np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 3))
    tag_losses(points, tags, ranges, sigma, anchors, np.zeros((0, 0)))
    tag_losses(points, tags, ranges, sigma, anchors, np.ones((7, 1)))
    link_floors(np.ones((7, 1)))
