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
How a calibration's residuals are correlated in time, and what that does to its deviations.

On a moving body a UWB link's noise is correlated over seconds (public recordings: 0.73 at
one frame, 0.50 at ten; three quarters of the variance with a correlation time of ~2.4 s).
:class:`NoiseCorrelation` models it as a share ``share`` of the variance with an exponential
memory of ``memory`` frames, the rest white: the autocorrelation at lag ``k >= 1`` is
``share a^k``, ``a = exp(-1 / memory)``; n frames of it weigh as n / ``time`` independent
ones, ``time = 1 + 2 share a / (1 - a)`` the integrated autocorrelation time.

:func:`fit_noise_correlation` fits it to the residuals' autocorrelation pooled over the
links. Each link's mean is taken off (a calibration fits every link's offset), which lowers
every lag's estimate by about ``time / n`` of the variance: over 600 frames correlated for
37, Sokal's windowed sum, which ignores that, reads about 20, and a calibration's deviations
from it were half what they should be. The model's expectation counts the drop.
"""
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

__all__ = ['NoiseCorrelation', 'fit_noise_correlation', 'integrated_autocorrelation',
           'pooled_autocorrelation']

#: The memories tried, frames: from white to the whole recording, about 10 % apart.
MEMORY_STEPS = 80
#: The shares tried, 0 to 1.
SHARE_STEPS = 41
#: Most lags fitted, frames (100 s at 10 Hz): a long recording's far lags add only cost.
MOST_LAGS = 1000


@dataclass(frozen=True)
class NoiseCorrelation:
    """White noise plus a share ``share`` of the variance remembered over ``memory`` frames."""

    share: float = 0.0
    memory: float = 0.0

    @property
    def decay(self):
        """Return the correlated part's correlation from one frame to the next."""
        return float(np.exp(-1.0 / self.memory)) if self.memory > 0 else 0.0

    @property
    def time(self):
        """Return the integrated autocorrelation time, frames (>= 1)."""
        decay = self.decay
        return 1.0 + 2.0 * self.share * decay / (1.0 - decay)

    def correlate(self, rows):
        """
        Return ``sum_s rho(t - s) rows[s]`` for every frame t.

        ``rows`` (n, ...) in time order, one frame a row; ``rho`` this autocorrelation. With
        a link's Jacobian rows it gives what its noise adds to the information's spread.
        """
        rows = np.asarray(rows, dtype=float)
        decay = self.decay
        if self.share == 0.0 or decay == 0.0:
            return rows.copy()
        forward = lfilter([1.0], [1.0, -decay], rows, axis=0)
        backward = lfilter([1.0], [1.0, -decay], rows[::-1], axis=0)[::-1]
        return (1.0 - self.share) * rows + self.share * (forward + backward - rows)


def pooled_autocorrelation(residuals, mask, lags):
    """
    Return the autocorrelation at lags 1..``lags`` pooled over links, and frames per link.

    Each link's products at a lag and their count summed over the links, by FFT.
    """
    counts = np.maximum(mask.sum(axis=0), 1)
    centred = np.where(mask, residuals - np.where(mask, residuals, 0.0).sum(axis=0) / counts,
                       0.0)
    variance = np.sum(centred ** 2) / max(mask.sum(), 1)
    if variance <= 0:
        return np.zeros(lags), float(np.mean(counts))
    size = 1 << int(2 * len(centred) - 1).bit_length()     # no wrap-around

    def lagged(series):
        spectrum = np.fft.rfft(series, size, axis=0)
        return np.fft.irfft(spectrum * spectrum.conj(), size, axis=0)[1:lags + 1].sum(axis=1)

    pairs = np.maximum(np.rint(lagged(mask.astype(float))), 1.0)
    return lagged(centred) / pairs / variance, float(np.mean(counts))


def fit_noise_correlation(residuals, mask):
    """
    Return the :class:`NoiseCorrelation` whose expected autocorrelation fits the residuals'.

    Parameters
    ----------
    residuals : ndarray, shape (n, links)
        Scaled residuals in time order, one frame a row.
    mask : ndarray of bool, shape (n, links)
        Where they count.

    Returns
    -------
    NoiseCorrelation
        Least squares over lags 1 to n / 4 (at most :data:`MOST_LAGS`) of the pooled
        autocorrelation against its expectation with each link's mean taken off,
        ``(share a^k - time / n) / (1 - time / n)``, over a grid of memories (0.3 frames to
        n, ~10 % apart) and shares (0 to 1).
        White (share 0) for fewer than 8 frames or residuals that do not vary.

    """
    residuals = np.asarray(residuals, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    frames = residuals.shape[0]
    if frames < 8:
        return NoiseCorrelation()
    lags = np.arange(1, min(frames // 4, MOST_LAGS) + 1)
    measured, per_link = pooled_autocorrelation(residuals, mask, lags.size)
    if not measured.any():
        return NoiseCorrelation()
    memories = np.geomspace(0.3, frames, MEMORY_STEPS)[:, None, None]
    shares = np.linspace(0.0, 1.0, SHARE_STEPS)[None, :, None]
    decays = np.exp(-1.0 / memories)
    times = 1.0 + 2.0 * shares * decays / (1.0 - decays)
    drop = np.minimum(times / per_link, 0.9)
    expected = (shares * decays ** lags - drop) / (1.0 - drop)
    cost = np.sum((measured - expected) ** 2, axis=-1)
    memory, share = np.unravel_index(np.argmin(cost), cost.shape)
    return NoiseCorrelation(share=float(shares[0, share, 0]),
                            memory=float(memories[memory, 0, 0]))


def integrated_autocorrelation(residuals, mask):
    """
    Return the residuals' integrated autocorrelation time, frames (>= 1).

    ``residuals`` (n, links) in time order, ``mask`` (n, links) where they count: the
    ``time`` of :func:`fit_noise_correlation`. n frames of it weigh as n / time independent
    ones.
    """
    return fit_noise_correlation(residuals, mask).time
