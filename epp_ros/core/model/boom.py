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
Boom geometry: section lengths, base pivot, anchors, and forward kinematics.

Conventions (REP 103, SI): world frame in metres with z up. Sections are numbered from the
base outward; section k (k = 1..p) has length ``arm_lengths[k-1]`` and joint k is its distal
end, joint p the tip. One UWB tag sits on each joint, anchors are at known positions.

Every UWB module adds a constant to the ranges it measures (its antenna delay is never
calibrated exactly): a measured tag-anchor range is the true distance plus
``tag_offsets[k] + anchor_offsets[j]``. :meth:`BoomModel.ranges` is the true distance,
:meth:`BoomModel.measured_ranges` what the modules report; ``Measurements.clean`` subtracts
the offsets once, so every method fits true distances.

The slew axis is vertical through ``base``. On real turntables the boom's pivot sits
``pivot_offset`` metres from that axis, along the slew direction, and moves on a circle as
the boom slews; with the default 0 the pivot is ``base`` itself, as in the paper.
"""
from epp_ros.core.model.plane import fit_slew
import numpy as np

__all__ = ['BoomModel', 'MAX_RANGE_OFFSET']


def _as_finite_array(value, field, ndim):
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{field} must be numeric, got {value!r}') from exc
    if array.ndim != ndim:
        raise ValueError(f'{field} must be a {ndim}-D array, got shape {array.shape}: {value!r}')
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{field} must be finite, got {value!r}')
    if np.any(np.abs(array) > MAX_METRES):
        raise ValueError(f'{field} must be within {MAX_METRES:g} m, got {value!r}')
    return array


#: Metres: no pump is larger; a bigger number is a unit or typing mistake (and would
#: overflow the geometry's squares).
MAX_METRES = 1e6


#: Metres: no UWB module's range offset is this large (antenna delays give tens of
#: centimetres); a bigger number is a unit or sign mistake.
MAX_RANGE_OFFSET = 10.0


def _offsets(value, field, count):
    """Return a device's range offsets (count,), metres: zeros for None, else validated."""
    if value is None:
        return np.zeros(count)
    offsets = _as_finite_array(value, field, 1)
    if offsets.shape != (count,):
        raise ValueError(f'{field} must hold {count} values (one per device), got '
                         f'{offsets.size}: {offsets.tolist()}')
    if np.any(np.abs(offsets) >= MAX_RANGE_OFFSET):
        raise ValueError(f'{field} must be within {MAX_RANGE_OFFSET:g} m, got '
                         f'{offsets.tolist()}')
    return offsets


#: Metres: anchors closer than this to each other, or all this close to one line, give the
#: ranges no geometry to locate a tag from (a configuration mistake, not a set-up).
ANCHOR_SEPARATION = 0.01


def _check_anchor_geometry(anchors):
    """Refuse coincident anchors, and anchors all on one line (rotation about it is free)."""
    gaps = np.linalg.norm(anchors[:, None] - anchors[None, :], axis=-1)
    gaps[np.diag_indices(len(anchors))] = np.inf
    first, second = np.unravel_index(np.argmin(gaps), gaps.shape)
    if gaps[first, second] < ANCHOR_SEPARATION:
        raise ValueError(f'anchors {min(first, second)} and {max(first, second)} are at the '
                         f'same point {anchors[first].tolist()}')
    centred = anchors - anchors.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    off_line = np.linalg.norm(centred - np.outer(centred @ direction, direction), axis=1)
    if off_line.max() < ANCHOR_SEPARATION:
        raise ValueError('anchors all lie on one line: they cannot tell a tag from its '
                         'rotation about it; place at least one off that line')


class BoomModel:
    """
    Geometry of a slewing, luffing boom and its UWB anchors.

    Parameters
    ----------
    arm_lengths : array_like, shape (p,)
        Section lengths in metres, base outward; finite and > 0, p >= 1.
    base : array_like, shape (3,)
        Base pivot (the first section's proximal joint) in the world frame, metres; with a
        ``pivot_offset``, the point of the slew axis at the pivot's height.
    anchors : array_like, shape (m, 3)
        Known anchor positions in the world frame, metres; m >= 3.
    pivot_offset : float
        Horizontal distance from the slew axis to the pivot, metres, positive along the
        slew direction. ``base`` is then the point of the slew axis at the pivot's height.
    anchor_offsets : array_like, shape (m,), optional
        Constant each anchor adds to the ranges it measures, metres (default zeros);
        finite, below ``MAX_RANGE_OFFSET`` in magnitude.
    tag_offsets : array_like, shape (p,), optional
        Constant each tag adds to the ranges it measures, metres (default zeros): a
        measured tag-anchor range is ``ranges(joints)[k, j] + tag_offsets[k] +
        anchor_offsets[j]``, a tag-tag range ``... + tag_offsets[k] + tag_offsets[l]``.
        Known offsets are subtracted from the measurements (``Measurements.clean``) and
        leave the Cramér–Rao bound unchanged: a known constant carries no information.
    pair_offsets : array_like, shape (p, m), optional
        What each tag-anchor link adds beyond its tag's and its anchor's offsets, metres
        (default zeros): real links have a bias of their own (antenna orientations, the
        path between the two devices), which ``core.calibrate`` estimates.

    Raises
    ------
    ValueError
        Naming the offending field and value.

    """

    def __init__(self, arm_lengths, base, anchors, pivot_offset=0.0, anchor_offsets=None,
                 tag_offsets=None, pair_offsets=None):
        arm_lengths = _as_finite_array(arm_lengths, 'arm_lengths', 1)
        if arm_lengths.size < 1:
            raise ValueError('arm_lengths must hold at least one section, got []')
        if np.any(arm_lengths <= 0):
            raise ValueError(f'arm_lengths must be > 0, got {arm_lengths.tolist()}')
        base = _as_finite_array(base, 'base', 1)
        if base.shape != (3,):
            raise ValueError(f'base must have shape (3,), got {base.shape}: {base.tolist()}')
        anchors = _as_finite_array(anchors, 'anchors', 2)
        if anchors.shape[1] != 3 or anchors.shape[0] < 3:
            raise ValueError(f'anchors must have shape (m, 3) with m >= 3, got {anchors.shape}')
        try:
            pivot_offset = float(pivot_offset)
        except (TypeError, ValueError) as exc:
            raise ValueError(f'pivot_offset must be a number, got {pivot_offset!r}') from exc
        if not np.isfinite(pivot_offset):
            raise ValueError(f'pivot_offset must be finite, got {pivot_offset!r}')
        _check_anchor_geometry(anchors)
        anchor_offsets = _offsets(anchor_offsets, 'anchor_offsets', anchors.shape[0])
        tag_offsets = _offsets(tag_offsets, 'tag_offsets', arm_lengths.size)
        shape = (arm_lengths.size, anchors.shape[0])
        pair_offsets = _offsets(None if pair_offsets is None else np.ravel(pair_offsets),
                                'pair_offsets', shape[0] * shape[1]).reshape(shape)
        self.arm_lengths = arm_lengths
        self.base = base
        self.pivot_offset = pivot_offset
        self.anchors = anchors
        self.anchor_offsets = anchor_offsets
        self.tag_offsets = tag_offsets
        self.pair_offsets = pair_offsets
        self._moves_with = np.tril(np.ones((arm_lengths.size, arm_lengths.size)))
        for array in (self.arm_lengths, self.base, self.anchors, self.anchor_offsets,
                      self.tag_offsets, self.pair_offsets):
            array.flags.writeable = False

    @property
    def n_sections(self):
        """Return the number of sections (and tags), p."""
        return self.arm_lengths.size

    @property
    def n_anchors(self):
        """Return the number of anchors, m."""
        return self.anchors.shape[0]

    @property
    def reach(self):
        """Sum of the section lengths, metres."""
        return float(self.arm_lengths.sum())

    def base_anchor(self, atol=1e-9):
        """Index of the anchor that sits at the base pivot, or None (also when it slews)."""
        if self.pivot_offset != 0.0:
            return None
        hits = np.flatnonzero(np.linalg.norm(self.anchors - self.base, axis=1) <= atol)
        return int(hits[0]) if hits.size else None

    def pivot(self, slew):
        """Return the boom's pivot for a slew (radians, shape (...)): shape (..., 3), metres."""
        slew = np.asarray(slew, dtype=float)
        return self.base + self.pivot_offset * np.stack(
            [np.cos(slew), np.sin(slew), np.zeros_like(slew)], axis=-1)

    def pivot_of(self, joints):
        """Return the pivot of an estimated boom (p, 3), at the slew its joints point along."""
        if self.pivot_offset == 0.0:
            return self.base.copy()
        joints = np.asarray(joints, dtype=float)
        if np.linalg.norm(joints[:, :2] - self.base[:2], axis=1).max() <= 1e-9:
            return self.pivot(0.0)          # straight up: no slew to read
        return self.pivot(fit_slew(joints, self.base))

    def forward_kinematics(self, slew, pitches):
        """
        Joint positions of the boom.

        Parameters
        ----------
        slew : float or ndarray, shape (...)
            Turntable angle about z, radians, from the world x-axis.
        pitches : ndarray, shape (..., p)
            Elevation of each section above the horizontal, radians.

        Returns
        -------
        joints : ndarray, shape (..., p, 3)
            ``w_k = pivot(theta) + sum_{i<=k} L_i (cos phi_i cos theta, cos phi_i sin theta,
            sin phi_i)``.

        """
        slew = np.asarray(slew, dtype=float)
        pitches = np.asarray(pitches, dtype=float)
        if pitches.shape[-1] != self.n_sections:
            raise ValueError(f'pitches must end in p={self.n_sections}, got {pitches.shape}')
        reach = self.pivot_offset + np.cumsum(self.arm_lengths * np.cos(pitches), axis=-1)
        height = np.cumsum(self.arm_lengths * np.sin(pitches), axis=-1)
        return self.base + np.stack([reach * np.cos(slew)[..., None],
                                     reach * np.sin(slew)[..., None], height], axis=-1)

    def joint_jacobian(self, slew, pitches):
        """
        Return the derivatives of the joints with respect to the posture angles.

        Parameters
        ----------
        slew : float or ndarray, shape (...)
            Radians.
        pitches : ndarray, shape (..., p)
            Radians.

        Returns
        -------
        jacobian : ndarray, shape (..., p, 3, p + 1)
            ``jacobian[k, :, 0] = dw_k/dslew``, ``jacobian[k, :, 1 + i] = dw_k/dpitch_i``
            (zero for sections beyond joint k).

        """
        slew = np.asarray(slew, dtype=float)[..., None]
        pitches = np.asarray(pitches, dtype=float)
        p = self.n_sections
        cos, sin = np.cos(slew), np.sin(slew)
        reach = self.pivot_offset + np.cumsum(self.arm_lengths * np.cos(pitches), axis=-1)
        # d/dpitch_i of section i's vector: L_i (-sin phi_i along + cos phi_i up).
        rise = self.arm_lengths * np.sin(pitches)
        section = np.stack([-rise * cos, -rise * sin,
                            self.arm_lengths * np.cos(pitches)], axis=-2)        # (..., 3, p)
        jacobian = np.zeros(pitches.shape[:-1] + (p, 3, p + 1))
        jacobian[..., 0, 0] = -reach * sin
        jacobian[..., 1, 0] = reach * cos
        # Joint k moves with sections i <= k.
        jacobian[..., 1:] = self._moves_with[:, None, :] * section[..., None, :, :]
        return jacobian

    @property
    def has_offsets(self):
        """Whether any device or link has a range offset."""
        return bool(self.anchor_offsets.any() or self.tag_offsets.any()
                    or self.pair_offsets.any())

    def link_offsets(self):
        """Return what each tag-anchor range measures too long, shape (p, m), metres."""
        return self.tag_offsets[:, None] + self.anchor_offsets[None, :] + self.pair_offsets

    def tag_link_offsets(self):
        """Return what each tag-tag range measures too long, shape (p, p), metres."""
        return self.tag_offsets[:, None] + self.tag_offsets[None, :]

    def ranges(self, joints):
        """
        Return the true tag-to-anchor distances, shape (..., p, m), metres.

        ``joints`` has shape (..., p, 3). Without the device offsets: what the methods
        fit, once ``Measurements.clean`` has taken the offsets off the measured ranges
        (:meth:`measured_ranges` adds them).
        """
        joints = np.asarray(joints, dtype=float)
        return np.linalg.norm(joints[..., :, None, :] - self.anchors, axis=-1)

    def measured_ranges(self, joints):
        """Return what the modules report, shape (..., p, m): :meth:`ranges` plus offsets."""
        return self.ranges(joints) + self.link_offsets()

    def with_calibration(self, anchors=None, anchor_offsets=None, tag_offsets=None,
                         pair_offsets=None, arm_lengths=None):
        """Return the same boom with other anchors, offsets or lengths (None: keep these)."""
        return BoomModel(self.arm_lengths if arm_lengths is None else arm_lengths, self.base,
                         self.anchors if anchors is None else anchors, self.pivot_offset,
                         self.anchor_offsets if anchor_offsets is None else anchor_offsets,
                         self.tag_offsets if tag_offsets is None else tag_offsets,
                         self.pair_offsets if pair_offsets is None else pair_offsets)

    def max_ranges(self):
        """Longest possible tag-anchor distances, shape (p, m): anchor to base plus reach."""
        to_base = np.linalg.norm(self.anchors - self.base, axis=1) + abs(self.pivot_offset)
        return np.cumsum(self.arm_lengths)[:, None] + to_base[None, :]

    def section_lengths(self, joints):
        """Lengths ``||w_k - w_{k-1}||`` (w_0: the pivot) of an estimated boom, (..., p)."""
        joints = np.asarray(joints, dtype=float)
        if self.pivot_offset == 0.0:
            base = np.broadcast_to(self.base, joints[..., :1, :].shape)
        else:
            flat = joints.reshape(-1, *joints.shape[-2:])
            base = np.stack([self.pivot_of(j) for j in flat]).reshape(joints[..., :1, :].shape)
        chain = np.concatenate([base, joints], axis=-2)
        return np.linalg.norm(np.diff(chain, axis=-2), axis=-1)

    def __repr__(self):
        offset = f', pivot_offset={self.pivot_offset}' if self.pivot_offset else ''
        if self.has_offsets:
            offset += (f', anchor_offsets={self.anchor_offsets.tolist()}, '
                       f'tag_offsets={self.tag_offsets.tolist()}')
        if self.pair_offsets.any():
            offset += f', pair_offsets={self.pair_offsets.tolist()}'
        return (f'BoomModel(arm_lengths={self.arm_lengths.tolist()}, base={self.base.tolist()}, '
                f'anchors={self.anchors.tolist()}{offset})')
