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
every link; its covariance ``(Lambda_0 + Lambda)^-1 S diag(link_std^2) S^T (Lambda_0 +
Lambda)^-1`` is kept beside the statistical one.

An anchor off the truck body (an outrigger's) may stand elsewhere than configured: set up
again, it is rarely where it was measured. Standing at ``a + delta`` it makes each of its
ranges ``-u . delta`` longer to first order, ``u`` the unit vector from the configured
anchor to the tag: a bias whose direction turns as the boom moves. Each such anchor adds
three columns ``-u`` (on its own links' rows, zero elsewhere) to ``D`` under a prior of
``anchor_std``. Learned (``learn_anchors``), the shifts come from the same frames as the
common bias. Each link's own bias moves the learned shift too (the floor above), and on
real links so do biases that turn with the boom, which the shifts then take for theirs.
Not learned (the default), a shift is only considered: never taken off the ranges, but
counted in :meth:`BiasLearner.covariance`, so the predicted joint stds count what a set-up
may have moved, however consistent the fit looks (a shifted outrigger moves the boom's fit,
not its residuals). What is counted is the shift's second moment given the frames, ``E[delta
delta^T] = delta_hat delta_hat^T + P``, from a learner beside it that does learn the shifts
(and whose estimate is used for nothing else): the prior's ``anchor_std^2`` at first, then
more where the frames show a shift, less where they show none. On real links that learner
takes some of the links' own biases for shifts too, and then only widens the stds.
"""
import numpy as np

__all__ = ['BiasLearner', 'REFERENCE_RANGE', 'bias_design']

#: Metres: the slope of the bias is taken about this range (a boom's ranges are ~5-45 m).
REFERENCE_RANGE = 20.0
#: Frames whose information a new frame's weighs as much as (the forgetting's memory).
MEMORY_FRAMES = 300
#: Largest bias (m) and slope (per metre) a pump's links may carry, and how far (m) along each
#: axis an anchor may stand from where configured: beyond, it is a fit gone wrong.
LIMITS = (2.0, 0.05)
ANCHOR_LIMIT = 3.0


def bias_design(distances, directions=None, anchors=None, moving=()):
    """
    Return the bias's directions: ``[1, r - REFERENCE_RANGE]``, then ``-u`` per moving anchor.

    Parameters
    ----------
    distances : array_like, shape (n,)
        The links' distances, metres.
    directions : array_like, shape (n, 3), optional
        Unit vectors from each link's configured anchor to its tag; None (or a moving
        anchor's rows NaN): its shift is not seen on those rows.
    anchors : array_like of int, shape (n,), optional
        Each link's anchor (index).
    moving : sequence of int
        The anchors whose shifts are parameters, in order.

    Returns
    -------
    ndarray, shape (n, 2 + 3 len(moving))

    """
    distances = np.asarray(distances, dtype=float)
    design = np.zeros(distances.shape + (2 + 3 * len(moving),))
    design[..., 0] = 1.0
    design[..., 1] = distances - REFERENCE_RANGE
    if moving and directions is not None:
        directions = np.nan_to_num(np.asarray(directions, dtype=float))
        for block, anchor in enumerate(moving):
            rows = np.asarray(anchors) == anchor
            design[rows, 2 + 3 * block:5 + 3 * block] = -directions[rows]
    return design


class BiasLearner:
    """
    The common range bias (offset at ``REFERENCE_RANGE`` and slope per metre), learned.

    Parameters
    ----------
    common_std : float
        Prior standard deviation of the offset, metres.
    slope_std : float
        Prior standard deviation of the slope, metres per metre.
    link_std : float or array_like, shape (p, m)
        Each link's own bias, metres (one for all, or one per link): the floor of what
        frames can tell of the common one.
    links : int
        How many links there are (p m): the columns of ``S``.
    memory : int
        Frames a new frame's information weighs as much as.
    anchor_std : float
        Prior standard deviation of each moving anchor's shift along each axis, metres.
    moving : sequence of int
        The anchors that may stand elsewhere than configured (indices).
    n_anchors : int
        How many anchors there are (m): a link's flat index ``k m + j`` names anchor j.
    learn_anchors : bool
        Learn the moving anchors' shifts; False: they stay at zero and are only counted
        in :meth:`covariance` (the prior, then what the frames show of them).

    Attributes
    ----------
    estimate : ndarray, shape (2 + 3 len(moving),)
        Offset (m) and slope (m/m) now taken off the ranges, then each moving anchor's
        shift (m).

    """

    def __init__(self, common_std, slope_std, link_std, links, memory=MEMORY_FRAMES,
                 anchor_std=0.0, moving=(), n_anchors=1, learn_anchors=False):
        self.moving = tuple(int(j) for j in moving)
        self.n_anchors = int(n_anchors)
        prior = np.array([common_std, slope_std, *[anchor_std] * (3 * len(self.moving))],
                         dtype=float)
        size = prior.size
        self.limits = np.r_[LIMITS, np.full(3 * len(self.moving), ANCHOR_LIMIT)]
        # Not learned, a shift is counted: all of it stays unknown to the estimate.
        self.considered = np.zeros(size, dtype=bool)
        self.considered[2:] = not learn_anchors
        self.considered &= prior > 0
        self.fixed = ~(prior > 0) | self.considered    # stays at 0
        # Beside, the same with the shifts learned: what frames say of them.
        self.shadow = BiasLearner(common_std, slope_std, link_std, links, memory, anchor_std,
                                  moving, n_anchors, learn_anchors=True) \
            if self.considered.any() else None
        self.prior_information = np.diag(np.where(self.fixed, 0.0, 1.0 / np.where(
            prior > 0, prior, 1.0) ** 2))
        #: Each link's own bias variance, m^2: one for all, or (links,) flat as the ranges.
        self.link_variance = np.ravel(np.asarray(link_std, dtype=float) ** 2) \
            if np.ndim(link_std) else float(link_std) ** 2
        self.forget = 1.0 - 1.0 / float(memory)
        self.information = np.zeros((size, size))
        self.weighted = np.zeros(size)                # information times the estimate
        self.through = np.zeros((size, int(links)))    # S: how each link's bias gets in
        self.estimate = np.zeros(size)
        self.frames = 0

    def correction(self, distances, directions=None):
        """
        Return the bias (m) to take off the (p, m) ranges of ``distances``, metres.

        ``directions`` (p, m, 3): unit vectors from each anchor to each tag; None: the
        anchors' shifts are left out.
        """
        distances = np.asarray(distances, dtype=float)
        anchors = np.broadcast_to(np.arange(distances.shape[-1]), distances.shape)
        design = bias_design(distances.ravel(), None if directions is None else
                             np.reshape(directions, (-1, 3)), anchors.ravel(), self.moving)
        return (design @ self.estimate).reshape(distances.shape)

    @property
    def anchor_shifts(self):
        """Return each moving anchor's learned shift (len(moving), 3), metres."""
        return self.estimate[2:].reshape(-1, 3)

    @property
    def seen_shifts(self):
        """
        Return each moving anchor's shift as the frames show it (len(moving), 3), m.

        The learned one, or, counted but not learned, that of the learner beside.
        """
        return (self if self.shadow is None else self.shadow).anchor_shifts

    def covariance(self):
        """
        Return what is not known of the bias (q, q).

        The estimate's share and the links' (the floor), and of the shifts counted but not
        learned their second moment.
        """
        statistical = self._statistical()
        return statistical + self._floor(statistical) + self._considered()

    def _considered(self):
        """Return the second moment (q, q) of the shifts counted but not learned."""
        size = self.estimate.size
        second = np.zeros((size, size))
        if self.shadow is not None:
            block = np.ix_(self.considered, self.considered)
            shift = self.shadow.estimate[self.considered]
            second[block] = self.shadow.covariance()[block] + np.outer(shift, shift)
        return second

    def _statistical(self):
        """Return ``(Lambda_0 + Lambda)^-1`` on the free parameters, zero elsewhere (q, q)."""
        total = self.prior_information + self.information
        free = ~self.fixed
        covariance = np.zeros(total.shape)
        covariance[np.ix_(free, free)] = np.linalg.inv(total[np.ix_(free, free)])
        return covariance

    def floor(self):
        """Return the covariance (q, q) the links' own biases leave in what is learned."""
        return self._floor(self._statistical())

    def _floor(self, statistical):
        """Return :meth:`floor` from :meth:`_statistical`'s covariance (q, q)."""
        carried = statistical @ self.through
        return (carried * self.link_variance) @ carried.T

    def observe(self, jacobian, sigma, residuals, distances, links, directions=None):
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
        directions : ndarray, shape (n, 3), optional
            Unit vectors from those links' anchors to their tags at the fit; None: the
            anchors' shifts learn nothing from this frame.

        """
        anchors = np.asarray(links) % self.n_anchors
        if self.shadow is not None and directions is not None:
            # Its residuals: of the ranges had its own estimate been taken off. (Its own
            # projection: the fit's bias stays bit for bit that of one not counting.)
            taken = self.shadow.estimate - self.estimate
            offset = bias_design(distances, directions, anchors, self.moving) @ taken
            self.shadow.observe(jacobian, sigma, residuals + offset / sigma, distances, links,
                                directions)
        free = ~self.fixed
        if directions is None:
            free[2:] = False
        if not free.any() or residuals.size <= jacobian.shape[1] + free.sum():
            return False
        design = bias_design(distances, directions, anchors, self.moving)[:, free] \
            / sigma[:, None]
        projected = design - jacobian @ np.linalg.lstsq(jacobian, design, rcond=None)[0]
        information = projected.T @ projected
        # The common bias alone: a frame that cannot tell it is skipped. An anchor's shift
        # is seen a direction at a time, so a frame adds what it tells and the prior and
        # other frames the rest.
        if not np.all(np.isfinite(information)) or (
                free.sum() == 2 and np.linalg.cond(information) > 1e12):
            return False
        # Information times the frame's own estimate, estimate + found, without solving.
        told = information @ self.estimate[free] - projected.T @ residuals
        through = np.zeros((free.sum(), self.through.shape[1]))
        through[:, links] = projected.T / sigma                  # D_perp^T Sigma^-1/2, 1/m
        self._add(free, information, told, through)
        return True

    def _add(self, free, information, told, through):
        """Fold in one frame's information on the ``free`` parameters, what it tells, S."""
        forget = self.forget if self.frames else 0.0
        block = np.ix_(free, free)
        self.information[block] = forget * self.information[block] + information
        self.weighted[free] = forget * self.weighted[free] + told
        self.through[free] = forget * self.through[free] + through
        self.frames += 1
        total = self.prior_information[block] + self.information[block]
        estimate = np.linalg.solve(total, self.weighted[free])
        self.estimate[free] = np.clip(estimate, -self.limits[free], self.limits[free])
