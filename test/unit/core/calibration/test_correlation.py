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

from epp_ros.core.calibration import fit_noise_correlation, integrated_autocorrelation
from epp_ros.core.calibration import NoiseCorrelation
from epp_ros.core.calibration.correlation import pooled_autocorrelation
import numpy as np


def correlated_series(rng, frames, links, share, memory):
    """Return unit-variance noise: ``share`` of it remembered over ``memory`` frames."""
    decay = np.exp(-1.0 / memory) if memory > 0 else 0.0
    slow = np.empty((frames, links))
    slow[0] = rng.standard_normal(links)
    for t in range(1, frames):
        slow[t] = decay * slow[t - 1] + np.sqrt(1 - decay ** 2) * rng.standard_normal(links)
    return np.sqrt(share) * slow + np.sqrt(1 - share) * rng.standard_normal((frames, links))


def test_integrated_autocorrelation_of_known_processes():
    """AR(1) of lag-one correlation rho: (1 + rho) / (1 - rho) frames; white noise: 1."""
    rng = np.random.default_rng(7)
    frames, links = 4000, 30
    series = correlated_series(rng, frames, links, 1.0, -1.0 / np.log(0.8))
    mask = rng.random(series.shape) > 0.1           # a tenth of the ranges missing
    # 120,000 draws correlated over 9 frames: the fit's spread is well under a frame.
    time = integrated_autocorrelation(series + 3.0, mask)     # each link's mean off
    assert abs(time - 9.0) < 2.0
    white = integrated_autocorrelation(rng.standard_normal((frames, links)), mask)
    assert 1.0 <= white < 1.3
    assert integrated_autocorrelation(np.zeros((10, 3)), np.ones((10, 3), bool)) == 1.0
    assert integrated_autocorrelation(np.ones((5, 3)), np.ones((5, 3), bool)) == 1.0


def test_a_minute_of_real_links_noise_reads_its_correlation():
    """
    600 frames of 30 links, 0.76 of the variance over 24 frames (real links on a body).

    Each link's mean taken off lowers every lag's correlation by time / n: Sokal's windowed
    sum read ~20 frames here for 36.7. Ten recordings: each within 40 %, their mean (its
    spread about 1.6 frames, measured) within 5 frames.
    """
    truth = NoiseCorrelation(share=0.76, memory=24.0)
    assert abs(truth.time - 36.7) < 0.1
    rng = np.random.default_rng(3)
    times = [integrated_autocorrelation(correlated_series(rng, 600, 30, 0.76, 24.0),
                                        np.ones((600, 30), bool)) for _ in range(10)]
    assert np.all(np.abs(np.array(times) / truth.time - 1.0) < 0.4)
    assert abs(np.mean(times) - truth.time) < 5.0
    fitted = fit_noise_correlation(correlated_series(rng, 6000, 30, 0.76, 24.0),
                                   np.ones((6000, 30), bool))
    assert abs(fitted.share - 0.76) < 0.1 and abs(fitted.memory / 24.0 - 1.0) < 0.25


def test_correlate_sums_the_rows_under_the_autocorrelation():
    """``correlate`` is the n x n autocorrelation matrix times the rows; white: the rows."""
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((50, 4, 3))
    correlation = NoiseCorrelation(share=0.6, memory=5.0)
    lags = np.abs(np.subtract.outer(np.arange(50), np.arange(50)))
    matrix = np.where(lags == 0, 1.0, 0.6 * correlation.decay ** lags)
    np.testing.assert_allclose(correlation.correlate(rows),
                               np.einsum('ts,slq->tlq', matrix, rows), atol=1e-12)
    assert correlation.time == 1.0 + 2.0 * 0.6 * correlation.decay / (1.0 - correlation.decay)
    np.testing.assert_array_equal(NoiseCorrelation().correlate(rows), rows)
    assert NoiseCorrelation().time == 1.0


def testpooled_autocorrelation_is_the_sum_over_links_of_their_lagged_products():
    """The FFT's sums against the lag-by-lag loop, with a mask and each link's mean off."""
    rng = np.random.default_rng(1)
    residuals = rng.standard_normal((300, 7)) + rng.normal(0.0, 2.0, 7)
    mask = rng.random(residuals.shape) > 0.2
    measured, per_link = pooled_autocorrelation(residuals, mask, 40)
    counts = mask.sum(axis=0)
    centred = np.where(mask, residuals - np.where(mask, residuals, 0.0).sum(axis=0) / counts,
                       0.0)
    variance = np.sum(centred ** 2) / mask.sum()
    looped = [np.sum(centred[lag:] * centred[:-lag]) / np.sum(mask[lag:] & mask[:-lag])
              / variance for lag in range(1, 41)]
    np.testing.assert_allclose(measured, looped, rtol=1e-10, atol=1e-12)
    assert per_link == counts.mean()
