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
One frame of what is measured about the boom, and how each measurement depends on the posture.

A frame holds the tag-anchor ranges (p, m) and, optionally, tag-tag ranges (p, p),
inclinometer pitches (p,) and a slew encoder reading, each with its own standard deviation
(:class:`SensorNoise`). :class:`Residuals` stacks them, scaled by their sigmas, with the
analytic Jacobian with respect to ``psi = (slew, pitch_1..pitch_p)``: the chain estimator's
least squares and the Cramér–Rao bound (``core.bounds``) share it.
"""
from dataclasses import dataclass
import math
import warnings

from epp_ros.core.model.noise import DEFAULT_NOISE
import numpy as np

__all__ = ['SensorNoise', 'Measurements', 'Residuals', 'plausible_limits', 'range_spikes',
           'SPIKE_M', 'wrap_angle']

INPUTS = ('ranges', 'tag_ranges', 'pitches', 'slew')


def wrap_angle(angle):
    """Angles (radians, any shape) wrapped into [-pi, pi)."""
    return np.mod(np.asarray(angle, dtype=float) + np.pi, 2 * np.pi) - np.pi


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the measurements (Gaussian, independent)."""

    range_sigma: float = DEFAULT_NOISE.sigma        #: m, tag-anchor ranges; scalar or (p, m)
    tag_sigma: float = DEFAULT_NOISE.sigma          #: m, tag-tag ranges
    pitch_sigma: float = DEFAULT_NOISE.pitch_sigma  #: rad, inclinometers
    slew_sigma: float = DEFAULT_NOISE.slew_sigma    #: rad, slew encoder

    def __post_init__(self):
        for name in ('range_sigma', 'tag_sigma', 'pitch_sigma', 'slew_sigma'):
            if not _finite_positive(getattr(self, name)):
                raise ValueError(f'{name} must be finite and > 0, got {getattr(self, name)!r}')


def _finite_positive(value):
    """Return whether ``value`` is a number or an array of numbers, all finite and > 0."""
    if isinstance(value, (float, int)):     # most noises: a frame builds several
        return math.isfinite(value) and value > 0
    try:
        value = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return bool(np.all(np.isfinite(value)) and np.all(value > 0))


def _clean(values, shape, field, limit=None):
    """Float array of ``shape``; non-finite or negative (when ``limit``) entries -> NaN."""
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{field} must be a numeric array of shape {shape}') from exc
    if array.shape != shape:
        raise ValueError(f'{field} must have shape {shape}, got {array.shape}')
    array[~np.isfinite(array)] = np.nan
    too_long = np.zeros(shape, bool)
    if limit is not None:
        with np.errstate(invalid='ignore'):
            array[array < 0] = np.nan
            too_long = array > limit
        array[too_long] = np.nan
    return array, int(too_long.sum())


def plausible_limits(model):
    """
    Longest believable tag-anchor (p, m) and tag-tag (p, p) distances, metres.

    Twice the longest the geometry allows plus 10 m: no noise or NLOS excess explains more.
    """
    reach = np.cumsum(model.arm_lengths)
    return (2.0 * model.max_ranges() + 10.0,
            2.0 * np.abs(reach[:, None] - reach[None, :]) + 10.0)


#: Metres a range may stand off the median of its link's neighbouring frames (five, itself
#: in the middle). The median follows any smooth motion, ramps exactly; UWB noise is a tenth
#: of this, so what stands off further is a wild range, not the boom.
SPIKE_M = 1.0


def range_spikes(ranges, limit=SPIKE_M, width=5):
    """
    Mask of the wild ranges of a recording: far off the median of their link's neighbours.

    Found again without those found, until no more are: wild ranges close together hide
    each other from one median.

    Parameters
    ----------
    ranges : ndarray, shape (N, ...)
        Frames in time order, metres; NaN where not measured.
    limit : float
        Metres a range may differ from the median of the ``width`` frames around it (NaN
        ignored).
    width : int
        Odd number of frames in the median.

    Returns
    -------
    ndarray of bool, shape (N, ...)

    """
    values = np.array(ranges, dtype=float)
    wild = np.zeros(values.shape, bool)
    while len(values):
        found = np.abs(values - _running_median(values, width)) > limit
        if not found.any():
            break
        wild |= found
        values[found] = np.nan
    return wild


def _running_median(values, width):
    """Median of each entry's ``width`` frames (N, ...) about it, NaN ignored (all NaN: NaN)."""
    from numpy.lib.stride_tricks import sliding_window_view
    half = width // 2
    pad = np.full((half, *values.shape[1:]), np.nan)
    windows = sliding_window_view(np.concatenate([pad, values, pad]), width, axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)     # all-NaN windows: NaN, kept
        return np.nanmedian(windows, axis=-1)


@dataclass(frozen=True)
class Measurements:
    """
    One frame of measurements; NaN marks what was not measured.

    Attributes
    ----------
    ranges : ndarray, shape (p, m)
        Tag-anchor distances, metres; row k the tag on joint k+1, column j anchor j.
    tag_ranges : ndarray, shape (p, p)
        Tag-tag distances, metres; every finite off-diagonal entry is one measurement
        (both ``[k, l]`` and ``[l, k]`` when both directions were ranged).
    pitches : ndarray, shape (p,)
        Inclinometer pitch of each section above the horizontal, radians.
    slew : float
        Slew encoder angle about z from the world x-axis, radians.
    stamp : float
        The frame's time, seconds (NaN: not known).
    range_stamps : ndarray, shape (p,), or None
        When each tag's ranges were measured, seconds on the clock of ``stamp``; NaN or
        None: at ``stamp``.

    """

    ranges: np.ndarray
    tag_ranges: np.ndarray
    pitches: np.ndarray
    slew: float
    stamp: float = float('nan')
    range_stamps: np.ndarray = None

    #: Largest believable distance, seconds, between a tag's measurement and its frame.
    LONGEST_DELAY = 1.0

    def delays(self):
        """
        Return each tag's measurement time less the frame's, seconds, shape (p,).

        Unknown times count as the frame's; delays beyond ``LONGEST_DELAY`` are clipped
        (a bad clock must not throw a tag a long way along its motion).
        """
        p = self.ranges.shape[0]
        if self.range_stamps is None or not np.isfinite(self.stamp):
            return np.zeros(p)
        delays = np.nan_to_num(self.range_stamps - self.stamp, nan=0.0, posinf=0.0,
                               neginf=0.0)
        return np.clip(delays, -self.LONGEST_DELAY, self.LONGEST_DELAY)

    @classmethod
    def clean(cls, model, ranges, tag_ranges=None, pitches=None, slew=None, limits=None,
              stamp=None, range_stamps=None):
        """
        Validate one frame for ``model``; unusable entries become NaN.

        NaN, inf and negative distances count as missing, and so do distances beyond
        ``limits`` (default :func:`plausible_limits`; pass them precomputed per frame).
        ``stamp`` (s) and ``range_stamps`` (p,) say when the frame and each tag's ranges
        were measured.

        The ranges are as the modules report them: the model's device offsets
        (``model.link_offsets()``, ``model.tag_link_offsets()``) are subtracted here, the
        one place every method's frames pass, so that the methods fit true distances
        (``model.ranges``); a corrected range below zero is taken as zero.

        Returns
        -------
        measurements : Measurements
        implausible : int
            How many finite, non-negative distances were dropped as too long.

        Raises
        ------
        ValueError
            On a wrong shape or a non-numeric value, naming the input.

        """
        p, m = model.n_sections, model.n_anchors
        range_limit, tag_limit = plausible_limits(model) if limits is None else limits
        ranges, too_long = _clean(ranges, (p, m), 'ranges', range_limit)
        if tag_ranges is None:
            tag_ranges = np.full((p, p), np.nan)
        else:
            tag_ranges, tag_too_long = _clean(tag_ranges, (p, p), 'tag_ranges', tag_limit)
            tag_ranges[np.diag_indices(p)] = np.nan
            too_long += tag_too_long
        if model.has_offsets:
            ranges = np.maximum(ranges - model.link_offsets(), 0.0)   # NaN stays NaN
            tag_ranges = np.maximum(tag_ranges - model.tag_link_offsets(), 0.0)
        pitches = np.full(p, np.nan) if pitches is None else \
            _clean(pitches, (p,), 'pitches')[0]
        slew = np.nan if slew is None else float(_clean(slew, (), 'slew')[0])
        stamp = np.nan if stamp is None else float(_clean(stamp, (), 'stamp')[0])
        if range_stamps is not None:
            range_stamps = _clean(range_stamps, (p,), 'range_stamps')[0]
        return cls(ranges, tag_ranges, pitches, slew, stamp, range_stamps), too_long

    @classmethod
    def ranges_only(cls, ranges):
        """Return a frame of tag-anchor ranges (p, m) alone (taken as they are: no offsets)."""
        ranges = np.asarray(ranges, dtype=float)
        p = ranges.shape[0]
        return cls(ranges, np.full((p, p), np.nan), np.full(p, np.nan), np.nan)

    def present(self):
        """Names of the inputs (``INPUTS``) with at least one measured value."""
        return [name for name in INPUTS if np.isfinite(getattr(self, name)).any()]

    def count(self):
        """Return the number of scalar measurements in the frame."""
        return int(sum(np.isfinite(getattr(self, name)).sum() for name in INPUTS))

    def with_ranges(self, ranges, tag_ranges=None):
        """Return the same frame with other ranges (e.g. with links removed)."""
        return Measurements(ranges, self.tag_ranges if tag_ranges is None else tag_ranges,
                            self.pitches, self.slew, self.stamp, self.range_stamps)


class Residuals:
    """
    Scaled residuals ``(predicted - measured) / sigma`` of a frame and their Jacobian.

    Rows are stacked as: tag-anchor links (row-major over the measured (k, j)), tag-tag
    links, inclinometers, the slew encoder. Angle residuals are wrapped into [-pi, pi).

    Parameters
    ----------
    model : BoomModel
    measurements : Measurements
    noise : SensorNoise

    """

    def __init__(self, model, measurements, noise):
        self.model = model
        self.noise = noise
        p = model.n_sections
        self.link_mask = np.isfinite(measurements.ranges)
        self.tag_mask = np.isfinite(measurements.tag_ranges)
        self.pitch_mask = np.isfinite(measurements.pitches)
        self.slew_measured = bool(np.isfinite(measurements.slew))
        self._tag, self._anchor = np.nonzero(self.link_mask)
        self._near, self._far = np.nonzero(self.tag_mask)
        self._pitch = np.flatnonzero(self.pitch_mask)
        self.n_ranged = self._tag.size + self._near.size
        slew = [measurements.slew] if self.slew_measured else []
        self.measured = np.concatenate([
            measurements.ranges[self.link_mask], measurements.tag_ranges[self.tag_mask],
            measurements.pitches[self.pitch_mask], slew])
        range_sigma = noise.range_sigma
        range_sigma = np.broadcast_to(range_sigma, self.link_mask.shape)[self.link_mask] \
            if np.ndim(range_sigma) else np.full(self._tag.size, float(range_sigma))
        self.sigma = np.concatenate([
            range_sigma, np.full(self._near.size, float(noise.tag_sigma)),
            np.full(self._pitch.size, float(noise.pitch_sigma)),
            [float(noise.slew_sigma)] if self.slew_measured else []])
        self._angle_index = np.concatenate([1 + self._pitch, [0] if slew else []]).astype(int)
        self._angle_rows = np.zeros((self._angle_index.size, p + 1))
        self._angle_rows[np.arange(self._angle_index.size), self._angle_index] = 1.0
        #: Which rows measure what, int64 each: (tag, anchor) of each tag-anchor range,
        #: (near, far) of each tag-tag range, the angle each angle row reads.
        self.layout = tuple(np.ascontiguousarray(index, dtype=np.int64) for index in (
            self._tag, self._anchor, self._near, self._far, self._angle_index))

    @property
    def size(self):
        """Return the number of residuals."""
        return self.measured.size

    def link_sigma(self):
        """Return the standard deviation (p, m) of each tag-anchor range, metres."""
        return np.broadcast_to(np.asarray(self.noise.range_sigma, dtype=float),
                               self.link_mask.shape)

    def ranged(self):
        """Boolean (size,): which rows are ranges (the ones NLOS can lengthen)."""
        return np.arange(self.size) < self.n_ranged

    def predict(self, psi):
        """
        Predicted measurements (size,) and the geometry the Jacobian needs.

        The geometry is ``(offsets, distances, joints)``; ``joints`` (p, 3) at ``psi``.
        """
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        offsets = np.concatenate([joints[self._tag] - self.model.anchors[self._anchor],
                                  joints[self._near] - joints[self._far]])
        distances = np.linalg.norm(offsets, axis=1)
        predicted = np.concatenate([distances, psi[self._angle_index]])
        return predicted, (offsets, distances, joints)

    def residuals(self, psi):
        """
        Return the scaled residuals at ``psi`` (p + 1,) and the geometry for :meth:`jacobian`.

        The scaled residuals have shape (size,).
        """
        predicted, geometry = self.predict(psi)
        difference = predicted - self.measured
        n = self.n_ranged
        difference[n:] = wrap_angle(difference[n:])
        return difference / self.sigma, geometry

    def timed(self, psi, rates, delays):
        """
        Scaled residuals and their Jacobian in (psi, rates) when tags ranged at other times.

        Tag k's ranges (to the anchors, and to the tags it measured) were taken ``delays[k]``
        seconds from the stamp ``psi`` describes, when the boom was at
        ``psi + delays[k] rates``; the angle sensors read at the stamp.

        Parameters
        ----------
        psi, rates : ndarray, shape (p + 1,)
            Angles (rad) and their rates (rad/s) at the stamp.
        delays : ndarray, shape (p,)
            Seconds.

        Returns
        -------
        scaled : ndarray, shape (size,)
        jacobian : ndarray, shape (size, 2 (p + 1))
        joints : ndarray, shape (p, 3)
            At the stamp.

        """
        p = self.model.n_sections
        postures = psi + np.r_[np.asarray(delays, dtype=float), 0.0][:, None] * rates
        boom = self.model.forward_kinematics(postures[:, 0], postures[:, 1:])  # (p + 1, p, 3)
        joint_jacobians = [self.model.joint_jacobian(posture[0], posture[1:])
                           for posture in postures[:p]]
        # Each tag at its own time; a tag-tag range at the measuring tag's.
        tags = np.arange(p)
        offsets = np.concatenate([boom[tags, tags][self._tag] - self.model.anchors[self._anchor],
                                  boom[self._near, self._near] - boom[self._near, self._far]])
        distances = np.linalg.norm(offsets, axis=1)
        difference = np.concatenate([distances, psi[self._angle_index]]) - self.measured
        n = self.n_ranged
        difference[n:] = wrap_angle(difference[n:])
        units = offsets / np.maximum(distances, 1e-12)[:, None]
        moved = np.array([joint_jacobians[k][k] for k in self._tag]
                         + [joint_jacobians[near][near] - joint_jacobians[near][far]
                            for near, far in zip(self._near, self._far)]).reshape(-1, 3, p + 1)
        rows = np.concatenate([np.einsum('nc,ncq->nq', units, moved), self._angle_rows])
        measuring = np.concatenate([self._tag, self._near]).astype(int)
        row_delays = np.r_[np.asarray(delays, dtype=float)[measuring],
                           np.zeros(len(self._angle_index))]
        jacobian = np.hstack([rows, rows * row_delays[:, None]]) / self.sigma[:, None]
        return difference / self.sigma, jacobian, boom[p]

    def jacobian(self, psi, geometry=None):
        """Jacobian of the scaled residuals, shape (size, p + 1)."""
        return self.rows(psi, geometry) / self.sigma[:, None]

    def rows(self, psi, geometry=None, joint_jacobian=None):
        """
        Jacobian of the residuals before scaling by sigma, shape (size, p + 1).

        ``joint_jacobian`` (p, 3, p + 1): the model's at ``psi``, when the caller has it.
        Unscaled, the rows stay valid when only the noise changes.
        """
        if geometry is None:
            geometry = self.predict(psi)[1]
        offsets, distances, _ = geometry
        units = offsets / np.maximum(distances, 1e-12)[:, None]
        if joint_jacobian is None:
            joint_jacobian = self.model.joint_jacobian(psi[0], psi[1:])
        moved = np.concatenate([joint_jacobian[self._tag],
                                joint_jacobian[self._near] - joint_jacobian[self._far]])
        return np.concatenate([np.einsum('nc,ncq->nq', units, moved), self._angle_rows])
