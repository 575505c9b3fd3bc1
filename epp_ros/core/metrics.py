"""Scores of estimated postures against the truth, as the paper defines them."""
import numpy as np

__all__ = ['joint_errors', 'frame_rmse', 'pooled_rmse']


def joint_errors(estimate, truth):
    """Euclidean error of each joint, metres: (..., p, 3) x2 -> (..., p)."""
    return np.linalg.norm(np.asarray(estimate) - np.asarray(truth), axis=-1)


def frame_rmse(estimate, truth):
    """The paper's RMSE of a frame, ``sqrt(sum_k ||w_hat_k - w_k||^2 / p)``: (..., p, 3) -> (...)."""
    return np.sqrt(np.mean(joint_errors(estimate, truth) ** 2, axis=-1))


def pooled_rmse(frame_rmses):
    """RMSE over many frames: the root of the mean of the squared frame RMSEs."""
    frame_rmses = np.asarray(frame_rmses, dtype=float)
    return float(np.sqrt(np.mean(frame_rmses ** 2))) if frame_rmses.size else float('nan')
