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
Blocked links persist: a link's NLOS state over time as a two-state Markov chain.

A body, a stack of formwork or the boom itself blocks a link for seconds, not for one
frame. ``core.nlos`` judges each range on its own, and an excess too small to tell from
the noise then passes as line of sight; over a recording those small excesses gather on
the links blocked longest and bias whatever is fitted to many frames (a calibration's
offsets). With the state a Markov chain in continuous time (in the long run a fraction
``f`` of the time blocked, visits lasting ``duration`` on average, exponentially
distributed, as ``simulate.FieldEffects``), the forward-backward recursion gives each range
the probability that its link is blocked *from the other frames*: the prior under which
the mixture then judges it (``NlosMixture.bind(sigma, prior)``). A frame amid a blocked
stretch is suspect even with a small excess, one amid clear frames is trusted.

``duration = 0`` is the frames each on their own: every prior is ``f``, the mixture as
before. :meth:`BlockageChain.learn` picks the duration of a recording by its marginal
likelihood over a grid that includes 0, so independent blockages are found as such.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ['BlockageChain', 'DURATIONS']

#: Durations tried by :meth:`BlockageChain.learn`, in frame periods (median elapsed time).
DURATIONS = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0)

#: Largest likelihood ratio a single range contributes (its log): a range hundreds of
#: sigmas long says no more than this, and the recursions stay finite.
_LOG_RATIO_LIMIT = 30.0


@dataclass(frozen=True)
class BlockageChain:
    """
    The NLOS state of every link: blocked a ``fraction`` of the time, for ``duration``.

    ``duration`` is in the unit of the elapsed times given to the methods (seconds, or
    frame periods); 0: each frame independent.
    """

    fraction: float
    duration: float

    def __post_init__(self):
        if not 0.0 < self.fraction < 1.0:
            raise ValueError(f'fraction must be in (0, 1), got {self.fraction}')
        if not self.duration >= 0.0:
            raise ValueError(f'duration must be >= 0, got {self.duration}')

    def transitions(self, elapsed):
        """
        Return P(blocked now | blocked before) and P(blocked now | clear before).

        Parameters
        ----------
        elapsed : ndarray, shape (n,)
            Time from each frame to the next, in the unit of ``duration``.

        Returns
        -------
        stay, enter : ndarray, shape (n,)

        """
        f = self.fraction
        if self.duration == 0.0:
            memory = np.zeros_like(np.asarray(elapsed, dtype=float))
        else:
            # Kept below 1: frames at one instant must not make the odds grow unbounded.
            memory = np.minimum(np.exp(-np.maximum(elapsed, 0.0)
                                       / (self.duration * (1.0 - f))), 1.0 - 1e-9)
        return f + (1.0 - f) * memory, f * (1.0 - memory)

    def priors(self, log_ratio, elapsed):
        """
        Return each range's NLOS probability given the other frames of its link.

        Parameters
        ----------
        log_ratio : ndarray, shape (n, links)
            ``log p(range | blocked) / p(range | clear)`` of each frame's range of each
            link (``LinkLoss.log_likelihood_ratio``), 0 where not measured; frames in
            time order.
        elapsed : ndarray, shape (n - 1,)
            Time between consecutive frames.

        Returns
        -------
        ndarray, shape (n, links)

        """
        steps = self._steps(log_ratio, elapsed)
        predicted, _ = self._forward(*steps)
        odds = predicted * self._backward(*steps)
        return odds / (odds + 1.0 - predicted)

    def log_likelihood(self, log_ratio, elapsed):
        """Return the log-likelihood of the ranges (up to a constant in the chain)."""
        return self._forward(*self._steps(log_ratio, elapsed))[1]

    @classmethod
    def learn(cls, fraction, log_ratio, elapsed, durations=DURATIONS):
        """
        Return the chain of the most likely of ``durations`` (times the median elapsed).

        Parameters as :meth:`priors`; ``fraction`` is the long-run blocked fraction.
        """
        step = float(np.median(elapsed)) if np.size(elapsed) else 1.0
        chains = [cls(fraction, duration * step) for duration in durations]
        scores = [chain.log_likelihood(log_ratio, elapsed) for chain in chains]
        return chains[int(np.argmax(scores))]

    def _steps(self, log_ratio, elapsed):
        """Return the likelihood ratios (n, links) and the transitions (n - 1,) of each step."""
        ratio = np.exp(np.clip(log_ratio, -_LOG_RATIO_LIMIT, _LOG_RATIO_LIMIT))
        return (ratio, *self.transitions(elapsed))

    def _forward(self, ratio, stay, enter):
        """Return P(blocked | earlier frames) (n, links) and the log-likelihood."""
        predicted = np.empty_like(ratio)
        blocked = np.full(ratio.shape[1], self.fraction)
        total = 0.0
        for n in range(ratio.shape[0]):
            if n:
                blocked = blocked * stay[n - 1] + (1.0 - blocked) * enter[n - 1]
            predicted[n] = blocked
            evidence = blocked * ratio[n] + 1.0 - blocked
            total += float(np.sum(np.log(evidence)))
            blocked = blocked * ratio[n] / evidence
        return predicted, total

    def _backward(self, ratio, stay, enter):
        """Return p(later frames | blocked) / p(later frames | clear), (n, links)."""
        backward = np.ones_like(ratio)
        for n in range(ratio.shape[0] - 2, -1, -1):
            later = ratio[n + 1] * backward[n + 1]
            backward[n] = (stay[n] * later + 1.0 - stay[n]) / (enter[n] * later + 1.0 - enter[n])
        return backward
