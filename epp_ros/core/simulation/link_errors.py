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
What real UWB links add to white noise: biases of their own, outliers, correlated noise.

Two-way-ranging recordings with motion-capture truth (DW1000 class) show that a link's
error is not a device offset plus white noise:

- each link has a bias of its own: a common part (the devices' median, ``range_bias``), a
  tag and an anchor term (``FieldEffects.tag_offset`` / ``anchor_offset``) and a part that
  belongs to the pair (``link_offset``: antenna orientations, the path between the two);
- the bias grows with range (``bias_curve``, piecewise linear, held beyond its ends) and
  moves when the tag turns relative to the anchor (``orientation_bias``: per link,
  ``a cos(phi) + b sin(phi)`` with ``a, b ~ N(0, s^2)``, phi the elevation of the anchor
  seen from the tag less the pitch of the tag's section, so its RMS over phi is s);
- outliers of a few frames (``outlier_rate`` per link and second, lasting
  ``outlier_duration`` on average, each frame of one off by ``N(0, outlier_size^2)``);
- on a moving body the noise is correlated over seconds: a fraction
  ``correlated_fraction`` of its variance is an Ornstein–Uhlenbeck process of correlation
  time ``noise_correlation_time``, the rest white (autocorrelation ``w exp(-dt / tau)``).

:class:`LinkErrors` holds one run's draws of these for a set of links; the field simulator
adds them to its ranges. Outliers, like the simulator's blocked links and silent tags, are
two-state chains stepped by :func:`markov_step`. It draws from its own generator, so that
runs without these effects keep every draw they had.
"""
import numpy as np

__all__ = ['LinkErrors', 'bias_at_range', 'markov_step']


def markov_step(bad, fraction, duration, elapsed, rng):
    """
    Return the next states of two-state chains after ``elapsed`` seconds.

    Parameters
    ----------
    bad : ndarray of bool
        The states now.
    fraction : float
        Long-run fraction of time in the bad state.
    duration : float
        Mean time a visit to the bad state lasts, seconds; 0: independent of ``bad``.
    elapsed : float
        Seconds, > 0.
    rng : numpy.random.Generator
        Draws the transitions.

    """
    memory = duration * (1.0 - fraction)        # correlation time, seconds
    decay = np.exp(-elapsed / memory) if memory > 0 else 0.0
    return rng.random(bad.shape) < fraction + (bad - fraction) * decay


def bias_at_range(curve, distances):
    """
    Return the range-dependent bias of links at ``distances`` (metres), same shape.

    ``curve`` is a sequence of (range m, bias m) knots in increasing range: linear between
    them, held beyond the ends; empty: zero.
    """
    distances = np.asarray(distances, dtype=float)
    if not curve:
        return np.zeros(distances.shape)
    knots = np.asarray(curve, dtype=float)
    return np.interp(distances, knots[:, 0], knots[:, 1])


def _elevation(tags, anchors):
    """Return the elevation (rad) of each anchor (m, 3) seen from each tag (p, 3): (p, m)."""
    offset = anchors[None] - tags[:, None]
    return np.arctan2(offset[..., 2], np.hypot(offset[..., 0], offset[..., 1]))


class LinkErrors:
    """
    One run's real-link errors on ``shape`` (tags, anchors) links; see the module.

    Parameters
    ----------
    effects : FieldEffects
        ``range_bias``, ``link_offset``, ``bias_curve``, ``orientation_bias``,
        ``outlier_rate``, ``outlier_duration``, ``outlier_size``, ``correlated_fraction``,
        ``noise_correlation_time``.
    shape : tuple of int
        (p, m): the links.
    rng : numpy.random.Generator
        Draws everything, constants first (link offsets, orientation coefficients, the
        correlated noise's and the outliers' first states), then each frame's.

    Attributes
    ----------
    link_offsets : ndarray, shape (p, m)
        Each link's own constant bias, metres (the pair term; without the common part).

    """

    def __init__(self, effects, shape, rng):
        self.effects, self.rng = effects, rng
        self.link_offsets = rng.normal(0.0, effects.link_offset, shape)
        self._orientation = rng.normal(0.0, effects.orientation_bias, (2,) + tuple(shape))
        self._slow = rng.standard_normal(shape)             # stationary from the start
        self._outlying = rng.random(shape) < self._outlier_fraction()

    def _outlier_fraction(self):
        effects = self.effects
        return min(effects.outlier_rate * effects.outlier_duration, 1.0)

    def same_links_as(self, other):
        """Give these links ``other``'s constants: their own offsets and orientation terms."""
        self.link_offsets = other.link_offsets.copy()
        self._orientation = other._orientation.copy()

    def step(self, elapsed):
        """Advance the correlated noise and the outlier states by ``elapsed`` seconds (> 0)."""
        effects, rng = self.effects, self.rng
        tau = effects.noise_correlation_time
        keep = np.exp(-elapsed / tau) if tau > 0 else 0.0
        self._slow = keep * self._slow + np.sqrt(1.0 - keep ** 2) * rng.standard_normal(
            self._slow.shape)
        self._outlying = markov_step(self._outlying, self._outlier_fraction(),
                                     effects.outlier_duration, elapsed, rng)

    def bias(self, distances, tags, anchors, pitches):
        """
        Return each link's bias now, metres (p, m), without the device offsets.

        Parameters
        ----------
        distances : ndarray, shape (p, m)
            True tag-anchor distances, metres.
        tags : ndarray, shape (p, 3)
            Where the tags are.
        anchors : ndarray, shape (m, 3)
            Where the anchors are.
        pitches : ndarray, shape (p,)
            The pitch of each tag's section, radians.

        """
        effects = self.effects
        phi = _elevation(tags, anchors) - np.asarray(pitches, dtype=float)[:, None]
        turning = self._orientation[0] * np.cos(phi) + self._orientation[1] * np.sin(phi)
        return (effects.range_bias + self.link_offsets + bias_at_range(effects.bias_curve,
                                                                       distances) + turning)

    def noise(self, sigma, white):
        """
        Return the noise of each link (p, m), metres, of standard deviation ``sigma``.

        ``white`` (standard normal) mixed with the correlated part by their shares.
        """
        share = self.effects.correlated_fraction
        return sigma * (np.sqrt(1.0 - share) * white + np.sqrt(share) * self._slow)

    def outliers(self):
        """Return each link's outlier excess now, metres (p, m): 0 where not outlying."""
        size = self.effects.outlier_size
        return self._outlying * self.rng.normal(0.0, size, self._outlying.shape)
