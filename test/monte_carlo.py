"""Statistical checks shared by the estimator tests."""
import numpy as np
import pytest


def assert_mse_at_bound(squared, bound_rmse, estimator):
    """Mean squared error of the trials at the bound, within 4 of its own standard errors.

    ``squared`` (trials,) holds each trial's mean squared joint error, m^2; the estimator's
    own predicted RMSE (from its Fisher information) must match the bound within 5 %.
    """
    squared = np.asarray(squared, dtype=float)
    standard_error = squared.std(ddof=1) / np.sqrt(squared.size)
    assert abs(squared.mean() - bound_rmse ** 2) < 4 * standard_error
    assert estimator.last_diagnostics['predicted_rmse'] == pytest.approx(bound_rmse, rel=0.05)
