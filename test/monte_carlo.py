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

"""Statistical checks shared by the estimator tests."""
import numpy as np
import pytest

#: The simulator's ranges carry no bias beyond the model's offsets, and its anchors stand
#: where configured: tests of that ideal world tell the estimator so (by default it allows
#: for the biases of real links and for outriggers set up again).
UNBIASED = {'link_bias_std': 0.0, 'common_bias_std': 0.0, 'bias_slope_std': 0.0,
            'anchor_std': 0.0}


def assert_mse_at_bound(squared, bound_rmse, estimator):
    """
    Mean squared error of the trials at the bound, within 4 of its own standard errors.

    ``squared`` (trials,) holds each trial's mean squared joint error, m^2; the estimator's
    own predicted RMSE (from its Fisher information, widened by the last frame's
    a-posteriori variance factor when its residuals were larger than their noise) must
    match the bound so widened within 5 %.
    """
    squared = np.asarray(squared, dtype=float)
    standard_error = squared.std(ddof=1) / np.sqrt(squared.size)
    assert abs(squared.mean() - bound_rmse ** 2) < 4 * standard_error
    diagnostics = estimator.last_diagnostics
    widened = bound_rmse * np.sqrt(diagnostics.variance_factor)
    assert diagnostics['predicted_rmse'] == pytest.approx(widened, rel=0.05)
