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
Simulated pumps: geometries, postures, range noise and working-cycle trajectories.

Everything takes an explicit ``numpy.random.Generator`` so that runs are reproducible.
"""
from dataclasses import dataclass

import numpy as np

from .model import BoomModel

__all__ = ['XIE3DIM', 'xie3dim', 'truck_pump', 'random_posture', 'RangeNoise', 'AngleNoise',
           'observe', 'Trajectory', 'working_cycle']

#: The seed paper's authors' published test geometry ("xie3dim", repository
#: daiyijue/EMBED-SRLS, file time-1.mat): anchor 0 is the base pivot; metres.
XIE3DIM = {
    'anchors': [[0.0, 0.0, 0.0], [15.0, 0.0, 0.0], [0.0, 15.0, 0.0], [10.0, 10.0, 20.0]],
    'base': [0.0, 0.0, 0.0],
    'true_joints': [[0.24, 0.08, 9.25], [3.59, 1.11, 15.29], [9.40, 2.91, 18.60],
                    [16.86, 5.22, 13.71], [20.09, 6.22, 4.75]],
    'published_rmse_m': {'EMBED_CEPP': 0.947, 'improved_variant': 0.842, 'SR-LS_3D': 2.27,
                         'SDP_3D': 1.687},
}


def xie3dim():
    """
    Return the authors' geometry: model with the arm lengths implied by its joints, and joints.

    Returns
    -------
    model : BoomModel
    true_joints : ndarray, shape (5, 3)

    """
    joints = np.array(XIE3DIM['true_joints'])
    base = np.array(XIE3DIM['base'])
    lengths = np.linalg.norm(np.diff(np.vstack([base, joints]), axis=0), axis=1)
    return BoomModel(lengths, base, XIE3DIM['anchors']), joints


def truck_pump(arm_lengths=(9.0, 7.0, 7.0, 9.0, 9.0), base_height=3.5, n_anchors=6):
    """
    Return a truck-mounted pump with anchors on the turret, chassis and outriggers.

    The truck's x-axis points forward, the slew axis is at the origin. Anchors, in order
    of preference: the base pivot on the turret, the four outrigger feet, the cab roof,
    the rear of the chassis. Heights differ so that the anchors span space.

    Parameters
    ----------
    arm_lengths : sequence of float
        Section lengths, metres, base outward.
    base_height : float
        Height of the base pivot above the ground, metres.
    n_anchors : int
        How many of the anchors above to use, 3 to 7.

    """
    candidates = np.array([
        [0.0, 0.0, base_height],        # turret, at the base pivot
        [2.6, 3.4, 0.4],                # front outriggers, extended
        [2.6, -3.4, 0.4],
        [-4.2, 3.0, 0.6],               # rear outriggers
        [-4.2, -3.0, 0.6],
        [5.3, 0.0, 3.2],                # cab roof
        [-5.8, 0.0, 1.9],               # rear of the chassis
    ])
    if not 3 <= n_anchors <= len(candidates):
        raise ValueError(f'n_anchors must be in [3, {len(candidates)}], got {n_anchors}')
    return BoomModel(arm_lengths, [0.0, 0.0, base_height], candidates[:n_anchors])


def random_posture(model, rng, min_height=0.5, max_tries=10000):
    """
    Draw a random working posture with every joint at least ``min_height`` above the ground.

    Slew uniform in [-pi, pi); first section pitched 10..85 deg, the others -70..70 deg.

    Returns
    -------
    slew : float
    pitches : ndarray, shape (p,)
    joints : ndarray, shape (p, 3)

    """
    p = model.n_sections
    low = np.radians(np.r_[10.0, np.full(p - 1, -70.0)])
    high = np.radians(np.r_[85.0, np.full(p - 1, 70.0)])
    for _ in range(max_tries):
        slew = rng.uniform(-np.pi, np.pi)
        pitches = rng.uniform(low, high)
        joints = model.forward_kinematics(slew, pitches)
        if joints[:, 2].min() >= min_height:
            return slew, pitches, joints
    raise RuntimeError('no posture above the ground found; check the model geometry')


@dataclass
class RangeNoise:
    """
    Range error model of the paper and of real UWB links.

    A measured range is ``d (1 + eta N1) + sigma N2 + NLOS``, clipped at zero, where N1, N2
    are standard normal, ``NLOS ~ Exponential(mean=nlos_gamma)`` on a random fraction
    ``nlos_fraction`` of the links (the always-positive excess of a blocked path), and each
    link is missing (NaN) with probability ``dropout``.
    """

    eta: float = 0.0            #: multiplicative noise factor (the paper's eta)
    sigma: float = 0.0          #: additive standard deviation, metres
    nlos_fraction: float = 0.0  #: probability that a link is non-line-of-sight
    nlos_gamma: float = 0.0     #: mean NLOS excess, metres
    dropout: float = 0.0        #: probability that a link is missing

    def apply(self, ranges, rng):
        """
        Noisy copy of true ``ranges`` (any shape).

        Returns
        -------
        noisy : ndarray
            Same shape, NaN where dropped.
        nlos : ndarray of bool
            Where an NLOS excess was added.

        """
        ranges = np.asarray(ranges, dtype=float)
        noisy = ranges * (1.0 + self.eta * rng.standard_normal(ranges.shape))
        noisy = noisy + self.sigma * rng.standard_normal(ranges.shape)
        nlos = rng.random(ranges.shape) < self.nlos_fraction
        if self.nlos_gamma > 0:
            noisy = noisy + nlos * rng.exponential(self.nlos_gamma, ranges.shape)
        noisy = np.maximum(noisy, 0.0)
        noisy[rng.random(ranges.shape) < self.dropout] = np.nan
        return noisy, nlos


@dataclass
class AngleNoise:
    """
    Errors of the paper's TPSM angle sensors.

    The slew encoder reads the slew plus a turntable error uniform in
    ``[-slew_error, slew_error]`` (the paper: +-0.5 deg); each inclinometer reads its
    section's pitch plus Gaussian noise of ``pitch_sigma`` (the paper gives no value).
    """

    slew_error: float = np.radians(0.5)     #: rad, bound of the uniform turntable error
    pitch_sigma: float = np.radians(0.5)    #: rad

    @property
    def slew_sigma(self):
        """Return the standard deviation of the slew error, radians."""
        return self.slew_error / np.sqrt(3.0)

    def apply(self, slew, pitches, rng):
        """Measured (slew, pitches) of a true posture."""
        pitches = np.asarray(pitches, dtype=float)
        return (float(slew + rng.uniform(-self.slew_error, self.slew_error)),
                pitches + self.pitch_sigma * rng.standard_normal(pitches.shape))


def observe(model, slew, pitches, rng, range_noise, tag_noise=None, angle_noise=None):
    """
    One simulated frame of a posture, as keyword arguments of ``PostureEstimator.update``.

    Parameters
    ----------
    model : BoomModel
        The boom and its anchors.
    slew : float
        Radians.
    pitches : ndarray, shape (p,)
        Section pitches, radians.
    rng : numpy.random.Generator
        Draws the noise.
    range_noise : RangeNoise
        Of the tag-anchor ranges.
    tag_noise : RangeNoise, optional
        Of tag-tag ranges between neighbouring joints (both directions); none without it.
    angle_noise : AngleNoise, optional
        Of an inclinometer on each section and a slew encoder; none without it.

    Returns
    -------
    frame : dict
        ``ranges`` (p, m) and, when simulated, ``tag_ranges`` (p, p), ``pitches`` (p,),
        ``slew``.
    nlos : ndarray of bool, shape (p, m)
        The tag-anchor links given an NLOS excess.

    """
    joints = model.forward_kinematics(slew, pitches)
    ranges, nlos = range_noise.apply(model.ranges(joints), rng)
    frame = {'ranges': ranges}
    if tag_noise is not None:
        p = model.n_sections
        neighbours = np.abs(np.subtract.outer(np.arange(p), np.arange(p))) == 1
        distances = np.linalg.norm(joints[:, None] - joints[None, :], axis=-1)
        tag_ranges, _ = tag_noise.apply(distances, rng)
        frame['tag_ranges'] = np.where(neighbours, tag_ranges, np.nan)
    if angle_noise is not None:
        frame['slew'], frame['pitches'] = angle_noise.apply(slew, pitches, rng)
    return frame, nlos


@dataclass
class Trajectory:
    """A sampled boom motion."""

    times: np.ndarray           #: (T,) seconds from the start
    slew: np.ndarray            #: (T,) radians
    pitches: np.ndarray         #: (T, p) radians
    joints: np.ndarray          #: (T, p, 3) metres


def working_cycle(model, duration, rate, rng=None, slew_amplitude=np.radians(60.0)):
    """
    Return a smooth pouring cycle: the boom sweeps in slew while its sections luff.

    Slew follows ``s0 + A sin(2 pi t / 40 s)``; each section's pitch oscillates by 10 deg
    about an unfolded pose (55 deg at the base down to -45 deg at the tip) with its own
    period (20-35 s) and phase; angular speeds stay below 0.17 rad/s, as on real pumps.

    Parameters
    ----------
    model : BoomModel
        The boom to move.
    duration : float
        Seconds.
    rate : float
        Samples per second.
    rng : numpy.random.Generator, optional
        Picks the start slew, periods and phases; fixed defaults without one.
    slew_amplitude : float
        Radians.

    Returns
    -------
    Trajectory

    """
    p = model.n_sections
    times = np.arange(int(round(duration * rate))) / rate
    if rng is None:
        start, periods, phases = 0.0, np.linspace(20.0, 35.0, p), np.zeros(p)
    else:
        start = rng.uniform(-np.pi, np.pi)
        periods = rng.uniform(20.0, 35.0, p)
        phases = rng.uniform(0.0, 2 * np.pi, p)
    rest = np.radians(np.linspace(55.0, -45.0, p) if p > 1 else np.array([30.0]))
    slew = start + slew_amplitude * np.sin(2 * np.pi * times / 40.0)
    pitches = rest + np.radians(10.0) * np.sin(2 * np.pi * times[:, None] / periods + phases)
    joints = model.forward_kinematics(slew, pitches)
    return Trajectory(times, slew, pitches, joints)
