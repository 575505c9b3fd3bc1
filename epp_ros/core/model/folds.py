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
The other postures a frame's ranges may fit as well: a joint folded, the tip at another pitch.

A joint between two others is fixed by the section lengths up to one reflection, across
the line through its neighbours; the tip hangs from one joint and may sit anywhere on its
circle. With few or weak ranges on that joint either can fit a frame about as well as the
estimate. Every search for them reads this module: the chain's and the tracker's restarts
(in angles), the field CEPP's (in joints), and the integrity checks that ask whether one
fits about as well as the estimate.
"""
from functools import lru_cache

from epp_ros.core.model.measurements import wrap_angle
import numpy as np

__all__ = ['TIP_PITCHES', 'reflect', 'fold_alternatives', 'folded_angles', 'keep_folds',
           'tip_circle', 'tip_minima']

#: Pitches of the tip's circle scanned for its other fits: 5 degrees apart.
TIP_PITCHES = 72


def reflect(points, inner, outer):
    """
    Return ``points`` (..., d) reflected across the lines from ``inner`` to ``outer`` (..., d).

    In the plane of each point and its line: the fold of a joint between two others.
    """
    axis = outer - inner
    axis = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    offset = points - inner
    return inner + 2.0 * np.sum(offset * axis, axis=-1, keepdims=True) * axis - offset


def fold_alternatives(model, joints):
    """
    Each inner joint reflected across the line through its neighbours.

    Reflection keeps both adjacent section lengths and, for a boom in a vertical plane,
    the plane: the other solution when the joint's own ranges are few or weak.

    Parameters
    ----------
    model : BoomModel
        The boom: its pivot and section lengths.
    joints : ndarray, shape (p, 3)
        A posture, metres.

    Returns
    -------
    alternatives : ndarray, shape (p - 1, 3)
        Row k: joint k (0-based, k < p - 1) folded; the others stay.

    """
    chain = np.vstack([model.pivot_of(joints), joints])
    return reflect(chain[1:-1], chain[:-2], chain[2:])


def folded_angles(model, psi):
    """
    Return the posture ``psi`` (slew, pitches) (p + 1,) with each joint folded, in angles.

    Folding joint k (:func:`fold_alternatives`) turns sections k and k + 1 about their
    chord: both pitches reflected across the chord's. A list of p - 1 arrays (p + 1,).
    """
    pitches = psi[1:]
    steps = model.arm_lengths[:, None] * np.c_[np.cos(pitches), np.sin(pitches)]
    chords = steps[:-1] + steps[1:]            # joint k - 1 to joint k + 1, k = 1..p-1
    axes = np.arctan2(chords[:, 1], chords[:, 0])
    folded = []
    for k, axis in enumerate(axes):
        turned = psi.copy()
        turned[1 + k:3 + k] = 2 * axis - pitches[k:k + 2]
        folded.append(wrap_angle(turned))
    return folded


def tip_circle(model, hinge, slew, pitches=TIP_PITCHES, section=-1):
    """
    Return the tip's positions at ``pitches`` pitches all round its ``hinge``, in the plane.

    Parameters
    ----------
    model : BoomModel
        The boom: its tip section's length.
    hinge : ndarray, shape (..., 3)
        The joint the tip section hangs from (the pivot for a one-section boom), metres;
        or several, each with its own circle.
    slew : float
        The boom's plane, radians.
    pitches : int
        How many, evenly spaced from -pi.
    section : int
        The section turned round its inner joint, ``hinge``: the tip's by default.

    Returns
    -------
    grid : ndarray, shape (pitches,)
        The section's pitches, radians (read-only: one array for every call).
    ends : ndarray, shape (..., pitches, 3)
        Its outer joint there, metres.

    """
    grid, cos, sin = _circle(pitches)
    ends = np.asarray(hinge, dtype=float)[..., None, :] + model.arm_lengths[section] * (
        cos * [np.cos(slew), np.sin(slew), 0.0] + sin * [0.0, 0.0, 1.0])
    return grid, ends


@lru_cache(maxsize=None)
def _circle(pitches):
    """Return ``pitches`` angles evenly from -pi, their cosines and sines (k, 1); read-only."""
    grid = np.linspace(-np.pi, np.pi, pitches, endpoint=False)
    parts = (grid, np.cos(grid)[:, None], np.sin(grid)[:, None])
    for part in parts:
        part.flags.writeable = False
    return parts


def tip_minima(loss, away):
    """
    Return the local minima of a loss on the tip's circle, lowest first, where ``away``.

    Parameters
    ----------
    loss : ndarray, shape (k,)
        Over a circular grid (:func:`tip_circle`).
    away : ndarray of bool, shape (k,)
        The grid points far enough from the estimate to be another fit.

    Returns
    -------
    ndarray of int
        Indices into the grid.

    """
    wrapped = np.concatenate((loss[-1:], loss, loss[:1]))       # the grid is a circle
    minima = np.flatnonzero((loss <= wrapped[:-2]) & (loss <= wrapped[2:]))
    minima = minima[away[minima]]
    return minima[np.argsort(loss[minima], kind='stable')]


def keep_folds(coords, reference, pivot, free, min_sine=0.05):
    """
    Fold back the free joints whose bend turned the other way than in ``reference``.

    A joint whose own ranges are missing but whose two neighbours are placed (the pivot
    counts) is fixed by the section lengths up to its fold: reflected across the line
    through its neighbours it fits as well. Such a joint is reflected when its bend (the
    turn from the inner section to the outer one) has the other sign than in
    ``reference`` while that bend was clear (its sine at least ``min_sine``): a fold
    no range saw happen is the reference's.

    Parameters
    ----------
    coords : ndarray, shape (p, 2)
        In-plane joint positions (reach, z), metres.
    reference : ndarray, shape (p, 2)
        The same joints before (e.g. the prior), metres.
    pivot : ndarray, shape (2,)
        In-plane position of the boom's pivot.
    free : ndarray of bool, shape (p,)
        Joints not placed by measurements of their own.
    min_sine : float
        Bends of ``reference`` with a smaller sine are taken as straight: either fold.

    Returns
    -------
    coords : ndarray, shape (p, 2)
        A copy, folded joints reflected.
    folded : ndarray of bool, shape (p,)

    """
    chain = np.vstack([pivot, coords]).astype(float)
    before = np.vstack([pivot, reference]).astype(float)
    placed = np.r_[True, ~np.asarray(free, dtype=bool), False]
    folded = np.zeros(chain.shape[0] - 1, bool)
    for i in np.flatnonzero(~placed[1:-1]) + 1:
        if not (placed[i - 1] and placed[i + 1]):
            continue                    # a run of free joints: nothing fixes the others
        now, then = _bend_sine(chain, i), _bend_sine(before, i)
        if abs(then) >= min_sine and now * then < 0:
            chain[i] = reflect(chain[i], chain[i - 1], chain[i + 1])
            folded[i - 1] = True
    return chain[1:], folded


def _bend_sine(chain, i):
    """Sine of the turn at chain point ``i`` from the section before it to the one after."""
    inner, outer = chain[i] - chain[i - 1], chain[i + 1] - chain[i]
    scale = np.linalg.norm(inner) * np.linalg.norm(outer)
    return float((inner[0] * outer[1] - inner[1] * outer[0]) / scale) if scale > 1e-12 else 0.0
