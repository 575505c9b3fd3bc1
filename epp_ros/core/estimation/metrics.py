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

"""Scores of estimated postures against the truth, as the paper defines them."""
import numpy as np

__all__ = ['joint_errors', 'frame_rmse', 'pooled_rmse', 'wrong_frames', 'WRONG_M',
           'COVERED_FRACTION']

#: Metres: a frame published as valid this far off is wrong for a pump's controller ...
WRONG_M = 1.0
#: ... and confidently so when its predicted RMSE is under this fraction of its error.
COVERED_FRACTION = 1.0 / 3.0


def joint_errors(estimate, truth):
    """Euclidean error of each joint, metres: (..., p, 3) x2 -> (..., p)."""
    return np.linalg.norm(np.asarray(estimate) - np.asarray(truth), axis=-1)


def frame_rmse(estimate, truth):
    """
    Return the paper's RMSE of a frame, ``sqrt(sum_k ||w_hat_k - w_k||^2 / p)``.

    Shapes: (..., p, 3) -> (...).
    """
    return np.sqrt(np.mean(joint_errors(estimate, truth) ** 2, axis=-1))


def pooled_rmse(frame_rmses):
    """RMSE over many frames: the root of the mean of the squared frame RMSEs."""
    frame_rmses = np.asarray(frame_rmses, dtype=float)
    return float(np.sqrt(np.mean(frame_rmses ** 2))) if frame_rmses.size else float('nan')


def wrong_frames(squared, published, predicted):
    """
    Return how many frames were published as valid while more than ``WRONG_M`` off.

    And of those, how many said so too little: a predicted RMSE under ``COVERED_FRACTION``
    of the error (or none). ``squared`` (T,): each frame's mean squared joint error, m^2;
    ``published`` (T,) bool; ``predicted`` (T,): the predicted RMSE, m (NaN: none).
    """
    error = np.sqrt(np.asarray(squared, dtype=float))
    wrong = np.asarray(published, dtype=bool) & (error > WRONG_M)
    confident = wrong & ~(np.asarray(predicted, dtype=float) >= COVERED_FRACTION * error)
    return int(wrong.sum()), int(confident.sum())
