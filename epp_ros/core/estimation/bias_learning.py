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
The range bias common to every link, learned from the estimator's own accepted frames.

Real UWB ranges are long by ~0.2-0.4 m at a boom's distances, more at longer ones
(``core.link_errors``). A fit absorbs most of such a bias by moving the boom (every tag
seems further from the truck), and what it cannot absorb is what shows: projecting a
frame's scaled residuals ``z`` on the part of the bias's directions ``D = [1, r - r0] /
sigma`` the fit's Jacobian ``A`` does not span, ``D_perp = (I - A F^-1 A^T) D``, estimates
the bias the ranges still carry, ``b = -(D_perp^T D_perp)^-1 D_perp^T z``, with information
``D_perp^T D_perp`` (large where the anchors see the tags from many directions).
Frames add their information, forgetting with a memory of ``memory`` frames; a Gaussian
prior (the told ``common_bias_std`` and ``bias_slope_std``) keeps the estimate at zero
until frames say otherwise. The estimator then takes the bias off every range, and the
integrity checks count what is still unknown of it (:meth:`BiasLearner.covariance`).

Each link's own bias ``e`` does not average out over frames: a frame's estimate carries
``(D_perp^T D_perp)^-1 D_perp^T Sigma^-1/2 e``, so the learned one carries ``(Lambda_0 +
Lambda)^-1 S e`` with ``S`` the frames' ``D_perp^T Sigma^-1/2`` summed (forgotten alike) over
every link; its covariance ``link_std^2 (Lambda_0 + Lambda)^-1 S S^T (Lambda_0 +
Lambda)^-1`` is kept beside the statistical one.
"""
import numpy as np

__all__ = ['BiasLearner', 'REFERENCE_RANGE', 'bias_design']

#: Metres: the slope of the bias is taken about this range (a boom's ranges are ~5-45 m).
REFERENCE_RANGE = 20.0
#: Frames whose information a new frame's weighs as much as (the forgetting's memory).
MEMORY_FRAMES = 300
#: Largest bias (m) and slope (per metre) a pump's links may carry: beyond, it is a fit gone
#: wrong, not a bias.
LIMITS = (2.0, 0.05)


def bias_design(distances):
    """Return the bias's directions ``[1, r - REFERENCE_RANGE]`` at ``distances`` (n,): (n, 2)."""
    distances = np.asarray(distances, dtype=float)
    return np.stack([np.ones(distances.shape), distances - REFERENCE_RANGE], axis=-1)


class BiasLearner:
    """
    The common range bias (offset at ``REFERENCE_RANGE`` and slope per metre), learned.

    Parameters
    ----------
    common_std : float
        Prior standard deviation of the offset, metres.
    slope_std : float
        Prior standard deviation of the slope, metres per metre.
    link_std : float
        Each link's own bias, metres: the floor of what frames can tell of the common one.
    links : int
        How many links there are (p m): the columns of ``S``.
    memory : int
        Frames a new frame's information weighs as much as.

    Attributes
    ----------
    estimate : ndarray, shape (2,)
        Offset (m) and slope (m/m) now taken off the ranges.

    """

    def __init__(self, common_std, slope_std, link_std, links, memory=MEMORY_FRAMES):
        prior = np.array([common_std, slope_std], dtype=float)
        self.fixed = ~(prior > 0)                  # a zero std: not learned, stays at 0
        self.prior_information = np.diag(np.where(self.fixed, 0.0, 1.0 / np.where(
            prior > 0, prior, 1.0) ** 2))
        self.link_std = float(link_std)
        self.forget = 1.0 - 1.0 / float(memory)
        self.information = np.zeros((2, 2))
        self.weighted = np.zeros(2)                # information times the estimate
        self.through = np.zeros((2, int(links)))    # S: how each link's bias gets in
        self.estimate = np.zeros(2)
        self.frames = 0

    def correction(self, distances):
        """Return the bias (m) to take off ranges of ``distances`` (any shape), metres."""
        return bias_design(distances) @ self.estimate

    def covariance(self):
        """Return what is not known of the bias (2, 2): the estimate's and the links' share."""
        return self._statistical() + self.floor()

    def _statistical(self):
        """Return ``(Lambda_0 + Lambda)^-1`` on the free parameters, zero elsewhere (2, 2)."""
        total = self.prior_information + self.information
        free = ~self.fixed
        covariance = np.zeros((2, 2))
        covariance[np.ix_(free, free)] = np.linalg.inv(total[np.ix_(free, free)])
        return covariance

    def floor(self):
        """Return the covariance (2, 2) the links' own biases leave in what is learned."""
        carried = self._statistical() @ self.through
        return self.link_std ** 2 * carried @ carried.T

    def observe(self, jacobian, sigma, residuals, distances, links):
        """
        Add a frame's accepted fit; return whether the estimate changed.

        Parameters
        ----------
        jacobian : ndarray, shape (n, q)
            Of the fit's scaled residuals over its line-of-sight links (rows / sigma).
        sigma : ndarray, shape (n,)
            Those links' standard deviations, metres.
        residuals : ndarray, shape (n,)
            Scaled residuals ``(fitted - measured) / sigma`` of the corrected ranges.
        distances : ndarray, shape (n,)
            Fitted distances of those links, metres.
        links : ndarray of int, shape (n,)
            Which links they are (flat indices of the (p, m) ranges).

        """
        free = ~self.fixed
        if not free.any() or residuals.size <= jacobian.shape[1] + 2:
            return False
        design = bias_design(distances)[:, free] / sigma[:, None]
        projected = design - jacobian @ np.linalg.lstsq(jacobian, design, rcond=None)[0]
        information = projected.T @ projected
        if np.linalg.cond(information) > 1e12:
            return False
        found = np.linalg.solve(information, -projected.T @ residuals)
        through = np.zeros((free.sum(), self.through.shape[1]))
        through[:, links] = projected.T / sigma                  # D_perp^T Sigma^-1/2, 1/m
        self._add(information, self.estimate[free] + found, through)
        return True

    def _add(self, information, value, through):
        """Fold in one frame's information on the free parameters, its estimate and S."""
        free = ~self.fixed
        forget = self.forget if self.frames else 0.0
        block = np.ix_(free, free)
        self.information[block] = forget * self.information[block] + information
        self.weighted[free] = forget * self.weighted[free] + information @ value
        self.through[free] = forget * self.through[free] + through
        self.frames += 1
        total = self.prior_information[block] + self.information[block]
        estimate = np.linalg.solve(total, self.weighted[free])
        self.estimate[free] = np.clip(estimate, -np.array(LIMITS)[free], np.array(LIMITS)[free])
