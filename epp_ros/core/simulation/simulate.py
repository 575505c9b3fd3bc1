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
Simulated pumps: geometries, postures, range noise, boom motions and a field simulator.

Everything takes an explicit ``numpy.random.Generator`` so that runs are reproducible.

- Geometries and postures: :func:`truck_pump`, :func:`xie3dim`, :func:`random_posture`.
- The paper's memoryless errors, frame by frame: :class:`RangeNoise`, :class:`AngleNoise`,
  :func:`observe`.
- Motions that give the posture at any time (a :class:`Motion`'s ``angles(times)`` and
  ``joints(times)``): :class:`WorkingMotion`, the smooth pouring cycle that
  :func:`working_cycle` samples into a :class:`Trajectory`, and :class:`JoystickMotion`, an
  operator's abrupt starts, stops and reversals.
- The field's departures from the configuration, :class:`FieldEffects` (named presets in
  :data:`FIELD_EFFECTS`, combined by :func:`field_effects`), played frame by frame by
  :class:`FieldSimulator` into :class:`FieldFrame` objects (:func:`simulate_field`: a run): a
  range sigma that grows with distance, constant per-device range offsets, anchors away
  from where the model puts them, NLOS blockages and silent tags that persist (two-state
  Markov chains), TDMA slot times, biased inclinometers and a slew encoder.
"""
from dataclasses import dataclass, fields
import operator

from epp_ros.core.model.boom import BoomModel
from epp_ros.core.simulation.link_errors import bias_at_range, LinkErrors, markov_step
import numpy as np

__all__ = ['XIE3DIM', 'xie3dim', 'truck_pump', 'BOOM_52M', 'TRUCK_BODY_ANCHORS',
           'truck_body_anchors', 'truck_outriggers', 'random_posture', 'RangeNoise', 'AngleNoise',
           'observe', 'Trajectory', 'working_cycle', 'Motion', 'WorkingMotion', 'StillMotion',
           'JoystickMotion', 'STOP_PROBABILITY', 'MOTIONS', 'make_motion', 'FieldEffects',
           'FIELD_EFFECTS', 'field_effects', 'FieldFrame', 'FieldSimulator', 'simulate_field']

#: The seed paper's authors' published test geometry ("xie3dim", repository
#: daiyijue/EMBED-SRLS, file time-1.mat): anchor 0 is the base pivot; metres. Their figures
#: at additive sigma = 1 m are over ``published_trials`` trials: the mean of the per-trial
#: RMSE (``published_mean_rmse_m``, what they printed) and its root mean square
#: (``published_rms_rmse_m``). Their CEPP took its plane from the true posture.
XIE3DIM = {
    'anchors': [[0.0, 0.0, 0.0], [15.0, 0.0, 0.0], [0.0, 15.0, 0.0], [10.0, 10.0, 20.0]],
    'base': [0.0, 0.0, 0.0],
    'true_joints': [[0.24, 0.08, 9.25], [3.59, 1.11, 15.29], [9.40, 2.91, 18.60],
                    [16.86, 5.22, 13.71], [20.09, 6.22, 4.75]],
    'published_trials': 3000,
    'published_sigma_m': 1.0,
    'published_mean_rmse_m': {'EMBED_CEPP': 0.947, 'improved_variant': 0.842,
                              'SR-LS_3D': 2.27, 'SDP_3D': 1.687},
    'published_rms_rmse_m': {'EMBED_CEPP': 0.997, 'improved_variant': 0.916,
                             'SR-LS_3D': 2.348, 'SDP_3D': 1.755},
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


#: :func:`truck_pump`'s anchors on the truck body (the turret, the cab roof, the chassis's
#: rear): they stay where configured and define the truck frame; the others, on the
#: outriggers, are set up anew on every site.
TRUCK_BODY_ANCHORS = (0, 5, 6)


def truck_outriggers(model):
    """Return the indices of :func:`truck_pump`'s outrigger anchors in ``model``."""
    return tuple(j for j in range(model.n_anchors) if j not in TRUCK_BODY_ANCHORS)


def truck_body_anchors(model):
    """Return the indices of :func:`truck_pump`'s anchors on the truck body in ``model``."""
    return tuple(j for j in TRUCK_BODY_ANCHORS if j < model.n_anchors)


#: ``truck_pump``'s keywords for a longer pump: six sections, 52 m, the pivot 4 m up.
BOOM_52M = {'arm_lengths': (10.0, 9.0, 9.0, 8.0, 8.0, 8.0), 'base_height': 4.0}


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


def _pitch_limits(p):
    """
    Return the working range of the pitches: first section 10..85 deg, the others -70..70.

    Returns
    -------
    low, high : ndarray, shape (p,)
        Radians.

    """
    return (np.radians(np.r_[10.0, np.full(p - 1, -70.0)]),
            np.radians(np.r_[85.0, np.full(p - 1, 70.0)]))


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
    low, high = _pitch_limits(model.n_sections)
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


class Motion:
    """
    A boom motion whose posture can be evaluated at any time.

    Subclasses set ``model`` (the :class:`BoomModel` that moves) and implement
    :meth:`angles`; :class:`FieldSimulator` takes any of them.
    """

    model: BoomModel

    def angles(self, times):
        """
        Return the posture angles at ``times``.

        Parameters
        ----------
        times : array_like, shape (T,)
            Seconds from the start of the motion (a scalar gives scalar-shaped results).

        Returns
        -------
        slew : ndarray, shape (T,)
            Radians.
        pitches : ndarray, shape (T, p)
            Section pitches, radians.

        """
        raise NotImplementedError

    def joints(self, times):
        """Return the joint positions at ``times`` (T,): shape (T, p, 3), metres."""
        slew, pitches = self.angles(times)
        return self.model.forward_kinematics(slew, pitches)


class StillMotion(Motion):
    """A boom that does not move: ``slew`` (rad) and ``pitches`` (p,) at every time."""

    def __init__(self, model, slew, pitches):
        self.model = model
        self.slew = float(slew)
        self.pitches = np.asarray(pitches, dtype=float)

    def angles(self, times):
        """Return the same slew (T,) and pitches (T, p) at ``times`` (:meth:`Motion.angles`)."""
        times = np.asarray(times, dtype=float)
        return (np.full(times.shape, self.slew),
                np.broadcast_to(self.pitches, times.shape + self.pitches.shape))


#: Seconds: period of the working cycle's slew sweep.
_SLEW_PERIOD = 40.0


class WorkingMotion(Motion):
    """
    The smooth pouring cycle: the boom sweeps in slew while its sections luff.

    Slew follows ``s0 + A sin(2 pi t / 40 s)``; each section's pitch oscillates by 10 deg
    about an unfolded pose (55 deg at the base down to -45 deg at the tip, 30 deg for a
    single section) with its own period (20-35 s) and phase; angular speeds stay below
    0.17 rad/s, as on real pumps.

    Parameters
    ----------
    model : BoomModel
        The boom to move.
    rng : numpy.random.Generator, optional
        Draws, in this order, the start slew s0 (uniform in [-pi, pi)), the p periods and
        the p phases; without one s0 = 0, periods evenly spaced over 20..35 s, phases 0.
    slew_amplitude : float
        A, radians.

    """

    def __init__(self, model, rng=None, slew_amplitude=np.radians(60.0)):
        p = model.n_sections
        if rng is None:
            start, periods, phases = 0.0, np.linspace(20.0, 35.0, p), np.zeros(p)
        else:
            start = rng.uniform(-np.pi, np.pi)
            periods = rng.uniform(20.0, 35.0, p)
            phases = rng.uniform(0.0, 2 * np.pi, p)
        self.model = model
        self.start, self.periods, self.phases = start, periods, phases
        self.slew_amplitude = slew_amplitude
        self.rest = np.radians(np.linspace(55.0, -45.0, p) if p > 1 else np.array([30.0]))

    def angles(self, times):
        """Return the cycle's slew (T,) and pitches (T, p) at ``times`` (:meth:`Motion.angles`)."""
        times = np.asarray(times, dtype=float)
        slew = self.start + self.slew_amplitude * np.sin(2 * np.pi * times / _SLEW_PERIOD)
        pitches = self.rest + np.radians(10.0) * np.sin(
            2 * np.pi * times[..., None] / self.periods + self.phases)
        return slew, pitches


def working_cycle(model, duration, rate, rng=None, slew_amplitude=np.radians(60.0)):
    """
    Return a smooth pouring cycle, :class:`WorkingMotion` sampled at ``rate``.

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
        At times ``0, 1/rate, ...``, ``round(duration * rate)`` samples.

    """
    times = np.arange(int(round(duration * rate))) / rate
    slew, pitches = WorkingMotion(model, rng, slew_amplitude).angles(times)
    return Trajectory(times, slew, pitches, model.forward_kinematics(slew, pitches))


#: Probability that a joystick is let go (its rate exactly 0) when its rate changes.
STOP_PROBABILITY = 1.0 / 3.0


class JoystickMotion(Motion):
    """
    An operator at the joysticks: each angle starts, stops and reverses abruptly.

    The slew and every pitch move at a rate that is constant for a hold time uniform in
    ``hold`` and then changes at once: to 0 (stopped) with probability
    :data:`STOP_PROBABILITY`, else to a rate uniform in [-max_rate, max_rate]. The boom
    starts at a :func:`random_posture`. The rates are integrated on a grid of ``step``
    seconds, where they also change: a pitch about to pass the limits of
    :func:`random_posture` reverses, the sections lowering a joint about to go below
    ``min_height`` reverse (and all pitches stop if that is not enough). The limits hold
    at every time; the height at every grid time (between grid times a joint can sag by
    ``reach (max_rate step)^2 / 8``, well under a millimetre).

    Between the breakpoints the angles are interpolated linearly, which is exact for
    piecewise-constant rates; before 0 and after the last breakpoint the boom stands still.

    Parameters
    ----------
    model : BoomModel
        The boom to move.
    duration : float
        Seconds of motion, > 0.
    rng : numpy.random.Generator
        Draws the start posture, then the rates and hold times.
    max_rate : float
        Fastest angular rate, rad/s.
    hold : (float, float)
        Shortest and longest time a rate is held, seconds.
    min_height : float
        Lowest a joint may go, metres above the ground (z = 0).
    step : float
        Grid of the rate changes, seconds.

    Attributes
    ----------
    breakpoints : ndarray, shape (B,)
        Seconds, from 0 to the end of the grid (at least ``duration``), where a rate may
        change.
    rates : ndarray, shape (B - 1, p + 1)
        Rad/s between consecutive breakpoints, slew first, then the pitches.

    """

    def __init__(self, model, duration, rng, max_rate=0.3, hold=(1.0, 6.0), min_height=0.5,
                 step=0.01):
        _check_positive('duration', duration)
        _check_positive('step', step)
        if not (np.isfinite(max_rate) and max_rate >= 0):
            raise ValueError(f'max_rate must be finite and >= 0 rad/s, got {max_rate!r}')
        shortest, longest = (float(value) for value in hold)
        if not (np.isfinite(longest) and 0 < shortest <= longest):
            raise ValueError(f'hold must be (shortest, longest) seconds with 0 < shortest <= '
                             f'longest, got {hold!r}')
        self.model, self.duration = model, float(duration)
        self.max_rate, self.hold = float(max_rate), (shortest, longest)
        self.min_height, self.step = float(min_height), float(step)
        self._low, self._high = _pitch_limits(model.n_sections)
        slew, pitches, _ = random_posture(model, rng, min_height)
        self._drive(np.r_[slew, pitches], int(np.ceil(self.duration / self.step - 1e-9)), rng)

    def angles(self, times):
        """Return the slew (T,) and pitches (T, p) at ``times`` (:meth:`Motion.angles`)."""
        times = np.asarray(times, dtype=float)
        angles = np.stack([np.interp(times, self.breakpoints, column)
                           for column in self._path.T], axis=-1)
        return angles[..., 0], angles[..., 1:]

    def _drive(self, start, steps, rng):
        """Integrate the rates over ``steps`` grid steps; keep breakpoints, angles, rates."""
        rates = np.zeros(start.size)
        due = np.zeros(start.size, dtype=int)      # grid step of each angle's next change
        index, angles = 0, start
        breakpoints, path, segments = [0.0], [start], []
        while index < steps:
            changing = due <= index
            rates[changing] = self._draw_rates(int(changing.sum()), rng)
            due[changing] = index + self._draw_holds(int(changing.sum()), rng)
            rates = self._steer(angles, rates)
            span = np.arange(1, min(due.min(), steps) - index + 1) * self.step
            ahead = angles + np.outer(span, rates)
            allowed = self._allowed(ahead)
            # The first step is allowed (steered); stop before the first that is not.
            run = len(ahead) if allowed.all() else int(np.argmin(allowed))
            index += run
            angles = ahead[run - 1]
            breakpoints.append(index * self.step)
            path.append(angles)
            segments.append(rates.copy())
        self.breakpoints = np.array(breakpoints)
        self._path = np.array(path)
        self.rates = np.array(segments).reshape(-1, start.size)

    def _draw_rates(self, count, rng):
        stopped = rng.random(count) < STOP_PROBABILITY
        return np.where(stopped, 0.0, rng.uniform(-self.max_rate, self.max_rate, count))

    def _draw_holds(self, count, rng):
        """Return hold times in grid steps, at least one."""
        return np.maximum(1, np.round(rng.uniform(*self.hold, count) / self.step)).astype(int)

    def _heights(self, pitches):
        return self.model.base[2] + np.cumsum(self.model.arm_lengths * np.sin(pitches), axis=-1)

    def _allowed(self, angles):
        """Whether postures (K, p + 1) keep the pitch limits and the joints above ground."""
        pitches = angles[:, 1:]
        within = ((pitches >= self._low) & (pitches <= self._high)).all(axis=1)
        return within & (self._heights(pitches).min(axis=1) >= self.min_height)

    def _steer(self, angles, rates):
        """Return the rates, reversed or stopped so that the next grid step is allowed."""
        rates = rates.copy()
        pitches, pitch_rates = angles[1:], rates[1:]       # a view: changes ``rates``
        ahead = pitches + self.step * pitch_rates
        past = (ahead < self._low) | (ahead > self._high)
        pitch_rates[past] = -pitch_rates[past]
        if self._allowed((angles + self.step * rates)[None])[0]:
            return rates
        # Pitches stay within +-90 deg: a section lowers its joints when its rate is < 0.
        sinking = np.flatnonzero(self._heights(pitches + self.step * pitch_rates)
                                 < self.min_height)
        if sinking.size:
            lowering = (pitch_rates < 0) & (np.arange(pitches.size) <= sinking.max())
            pitch_rates[lowering] = -pitch_rates[lowering]
        if not self._allowed((angles + self.step * rates)[None])[0]:
            pitch_rates[:] = 0.0
        return rates


#: Names of the motions :func:`make_motion` builds.
MOTIONS = ('working', 'joystick')


def make_motion(name, model, duration, rng):
    """
    Return the motion named ``name`` of :data:`MOTIONS` for a run of ``duration`` seconds.

    ``'working'``: :class:`WorkingMotion` (any length); ``'joystick'``:
    :class:`JoystickMotion` over ``duration``. ``rng`` draws its parameters.
    """
    if name == 'working':
        return WorkingMotion(model, rng)
    if name == 'joystick':
        return JoystickMotion(model, duration, rng)
    raise ValueError(f'unknown motion {name!r}; valid: {", ".join(MOTIONS)}')


def _check_positive(name, value):
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f'{name} must be finite and > 0, got {value!r}')


def _effect_number(name, value, high=np.inf, positive=False, low=0.0):
    """Return ``value`` as a float in [low, high] (or (0, high]); ValueError naming the field."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'FieldEffects.{name} must be a number, got {value!r}') from None
    if not (np.isfinite(number) and low <= number <= high and (number > 0 or not positive)):
        interval = f'{"(" if positive else "["}{low:g}, {high:g}]'
        raise ValueError(f'FieldEffects.{name} must be finite and in {interval}, got {value!r}')
    return number


def _bias_curve(value):
    """Return ``value`` as a tuple of finite (range, bias) pairs in increasing range."""
    try:
        knots = np.asarray(value, dtype=float).reshape(-1, 2) if len(value) else np.zeros((0, 2))
    except (TypeError, ValueError):
        raise ValueError('FieldEffects.bias_curve must be (range m, bias m) pairs, got '
                         f'{value!r}') from None
    if not np.all(np.isfinite(knots)) or np.any(np.diff(knots[:, 0]) <= 0) or np.any(
            knots[:, 0] < 0):
        raise ValueError('FieldEffects.bias_curve must be finite (range m, bias m) pairs in '
                         f'increasing range >= 0, got {value!r}')
    return tuple((float(r), float(b)) for r, b in knots)


def _anchor_indices(value):
    """Return ``value`` as a tuple of distinct anchor indices >= 0, or None."""
    if value is None:
        return None
    try:
        indices = tuple(operator.index(index) for index in value)
    except TypeError:
        raise ValueError('FieldEffects.moving_anchors must be None or anchor indices, got '
                         f'{value!r}') from None
    if any(index < 0 for index in indices) or len(set(indices)) != len(indices):
        raise ValueError('FieldEffects.moving_anchors must be distinct indices >= 0, got '
                         f'{value!r}')
    return indices


@dataclass(frozen=True)
class FieldEffects:
    """
    How a pump in the field departs from its configuration; each effect is off by default.

    A measured range is ``r + o_tag + o_anchor + b_link + (sigma + sigma_per_metre r) N +
    X``, clipped at zero, where r is the true distance from the tag to the anchor's TRUE
    position, N standard normal, ``o`` the per-device offsets, ``b_link`` what real links
    add (a common bias, a pair term, growth with range and with the tag's orientation,
    outliers; all zero by default; see :mod:`epp_ros.core.simulation.link_errors`) and X the NLOS
    excess. With ``correlated_fraction`` > 0 part of N is correlated in time.

    Persistent conditions (a blocked link, a silent tag) are two-state Markov chains in
    continuous time, one per link or tag: in the long run a fraction ``f`` of the time in
    the bad state, whose visits last ``D`` seconds on average (exponentially distributed).
    They start in their stationary distribution and are stepped at each frame with the
    exact probabilities for the time elapsed ``dt``: ``P(bad) = f + (s - f)
    exp(-dt / (D (1 - f)))``, s = 1 if bad before, else 0. ``D = 0``: drawn anew each frame.

    An inclinometer's bias is the boom's deflection, slowly varying: for section k,
    ``b_k(t) = c_k + a_k sin(2 pi t / bias_period + psi_k)`` with ``c_k ~ N(0, s^2 / 2)``,
    ``a_k ~ N(0, s^2)``, ``psi_k`` uniform, drawn once per run (s = ``inclinometer_bias``):
    half its variance constant, half a sinusoid, so that at a random time ``b_k`` has
    standard deviation s.

    Raises
    ------
    ValueError
        Naming the field, on a negative, non-finite or out-of-range value.

    """

    sigma: float = 0.1                  #: m, additive range standard deviation sigma0
    sigma_per_metre: float = 0.0        #: k: a range r has sigma ``sigma0 + k r``
    tag_offset: float = 0.0             #: m, std of each tag's constant range offset
    anchor_offset: float = 0.0          #: m, std of each anchor's constant range offset
    anchor_shift: float = 0.0           #: m per axis, std of where a moving anchor really is
    moving_anchors: tuple = None        #: anchors that move; None: all but the base anchor
    nlos_fraction: float = 0.0          #: long-run fraction of time a link is blocked
    nlos_duration: float = 2.0          #: s, mean time a blockage lasts
    nlos_gamma: float = 1.0             #: m, mean exponential excess, anew each frame
    dropout_fraction: float = 0.0       #: long-run fraction of time a tag is silent
    dropout_duration: float = 3.0       #: s, mean time a tag stays silent
    link_dropout: float = 0.0           #: probability that one range is missing
    tdma: bool = False                  #: each tag ranges in its own slot of the frame
    inclinometers: bool = False         #: simulate an inclinometer on each section
    pitch_sigma: float = float(np.radians(0.5))    #: rad, inclinometer noise
    inclinometer_bias: float = 0.0      #: rad, std of each inclinometer's slow bias
    bias_period: float = 120.0          #: s, period of the bias's slow part
    slew_encoder: bool = False          #: simulate a slew encoder
    slew_error: float = float(np.radians(0.5))     #: rad, bound of its uniform error
    range_bias: float = 0.0             #: m, bias common to every link (may be < 0)
    link_offset: float = 0.0            #: m, std of each link's own constant bias (pair)
    bias_curve: tuple = ()              #: ((m, m), ...): bias by range, piecewise linear
    orientation_bias: float = 0.0       #: m, RMS of a link's bias with the tag's pitch
    outlier_rate: float = 0.0           #: outliers per link and second
    outlier_duration: float = 0.25      #: s, mean length of one
    outlier_size: float = 1.0           #: m, std of an outlier's excess (signed)
    correlated_fraction: float = 0.0    #: share of the noise variance correlated in time
    noise_correlation_time: float = 2.4     #: s, of that share

    def __post_init__(self):
        for name in ('sigma', 'sigma_per_metre', 'tag_offset', 'anchor_offset',
                     'anchor_shift', 'nlos_duration', 'nlos_gamma', 'dropout_duration',
                     'pitch_sigma', 'inclinometer_bias', 'slew_error', 'link_offset',
                     'orientation_bias', 'outlier_rate', 'outlier_duration', 'outlier_size',
                     'noise_correlation_time'):
            object.__setattr__(self, name, _effect_number(name, getattr(self, name)))
        for name in ('nlos_fraction', 'dropout_fraction', 'link_dropout',
                     'correlated_fraction'):
            object.__setattr__(self, name, _effect_number(name, getattr(self, name), high=1.0))
        object.__setattr__(self, 'range_bias', _effect_number(
            'range_bias', self.range_bias, low=-np.inf))
        object.__setattr__(self, 'bias_curve', _bias_curve(self.bias_curve))
        object.__setattr__(self, 'bias_period',
                           _effect_number('bias_period', self.bias_period, positive=True))
        for name in ('tdma', 'inclinometers', 'slew_encoder'):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f'FieldEffects.{name} must be True or False, got '
                                 f'{getattr(self, name)!r}')
            object.__setattr__(self, name, bool(getattr(self, name)))
        object.__setattr__(self, 'moving_anchors', _anchor_indices(self.moving_anchors))


#: Named field effects, one effect each, with magnitudes seen on real pumps.
FIELD_EFFECTS = {
    'sigma_high': FieldEffects(sigma=0.3),
    'sigma_low': FieldEffects(sigma=0.01),
    'sigma_distance': FieldEffects(sigma=0.03, sigma_per_metre=0.01),
    'nlos_persistent': FieldEffects(nlos_fraction=0.2, nlos_duration=3.0, nlos_gamma=1.0),
    'tdma': FieldEffects(tdma=True),
    'dropouts': FieldEffects(dropout_fraction=0.1, dropout_duration=3.0),
    'offsets': FieldEffects(tag_offset=0.1, anchor_offset=0.1),
    'anchors_moved': FieldEffects(anchor_shift=0.2),
    'inclinometer_bias': FieldEffects(inclinometers=True,
                                      inclinometer_bias=float(np.radians(2.0))),
    # Real DW1000-class links (public two-way-ranging recordings with motion-capture
    # truth; an outdoor DWM1001 one for the range curve): link biases +0.04 / +0.18 /
    # +0.33 m at the 5th / 50th / 95th percentile, of which ~4.5 cm RMS belongs to the
    # pair; +-6 cm with the tag's orientation; -1 cm at 2-6 m, +23 cm at 25 m, +30 cm at
    # 55 m; sigma 6-8 cm on a moving body, autocorrelation 0.73 at one frame and 0.50 at
    # ten (76 % of the variance with a 2.4 s correlation time); ~33 outliers of 1-4
    # frames per link-hour, the largest +-3.3 m.
    'real_uwb': FieldEffects(sigma=0.07, range_bias=0.18, tag_offset=0.05, anchor_offset=0.05,
                             link_offset=0.045, orientation_bias=0.06,
                             bias_curve=((2.0, -0.01), (6.0, -0.01), (25.0, 0.23),
                                         (55.0, 0.30)),
                             outlier_rate=33.0 / 3600.0, outlier_duration=0.25,
                             outlier_size=1.0, correlated_fraction=0.76,
                             noise_correlation_time=2.4),
}


def field_effects(names):
    """
    Combine named presets of :data:`FIELD_EFFECTS` into one :class:`FieldEffects`.

    Parameters
    ----------
    names : str or iterable of str
        Preset names, or one comma-separated string of them.

    Returns
    -------
    FieldEffects
        Each field from the first preset, in the order given, that sets it to other than
        its default; the default where none does.

    Raises
    ------
    ValueError
        On no names or an unknown one, listing the valid names.

    """
    names = [name.strip() for name in (names.split(',') if isinstance(names, str) else names)]
    unknown = [name for name in names if name not in FIELD_EFFECTS]
    if unknown or not names:
        given = f'unknown field effect {", ".join(map(repr, unknown))}' if unknown \
            else 'no field effect named'
        raise ValueError(f'{given}; valid: {", ".join(FIELD_EFFECTS)}')
    default, chosen = FieldEffects(), {}
    for name in names:
        for field in fields(FieldEffects):
            value = getattr(FIELD_EFFECTS[name], field.name)
            if field.name not in chosen and value != getattr(default, field.name):
                chosen[field.name] = value
    return FieldEffects(**chosen)


@dataclass
class FieldFrame:
    """One frame of the field: what the sensors report, and the truth."""

    stamp: float                #: seconds
    ranges: np.ndarray          #: (p, m) metres, NaN where missing
    range_stamps: np.ndarray    #: (p,) seconds, when each tag ranged (``stamp`` w/o TDMA)
    pitches: np.ndarray         #: (p,) radians from the inclinometers, or None
    slew: float                 #: radians from the slew encoder, or None
    joints: np.ndarray          #: (p, 3) metres, the true joints at ``stamp``
    slew_true: float            #: radians, at ``stamp``
    pitches_true: np.ndarray    #: (p,) radians, at ``stamp``
    nlos: np.ndarray            #: (p, m) bool, the links blocked (given an NLOS excess)
    silent: np.ndarray          #: (p,) bool, the tags silent (their rows NaN)

    def inputs(self):
        """
        Return the frame as keyword arguments of ``PostureEstimator.update``.

        Returns
        -------
        dict
            ``ranges``, ``stamp``, ``range_stamps``, and ``pitches`` and ``slew`` when
            simulated.

        """
        inputs = {'ranges': self.ranges, 'stamp': self.stamp,
                  'range_stamps': self.range_stamps}
        if self.pitches is not None:
            inputs['pitches'] = self.pitches
        if self.slew is not None:
            inputs['slew'] = self.slew
        return inputs


class FieldSimulator:
    """
    Plays :class:`FieldEffects` frame by frame on any :class:`Motion`.

    The per-run constants are drawn at construction, in this order: the anchor shifts,
    the tag offsets, the anchor offsets, the inclinometer biases (constant parts,
    amplitudes, phases), then the first states of the NLOS and silence chains; last a child
    generator is spawned for :meth:`anchor_ranges`, so that its draws leave the frames'.

    Parameters
    ----------
    model : BoomModel
        The boom and the anchors as configured.
    effects : FieldEffects
        The field's departures from the configuration.
    rng : numpy.random.Generator, optional
        Draws everything; seeded with 0 without one.
    frame_period : float
        Seconds between frames: the TDMA frame.

    Attributes
    ----------
    true_anchors : ndarray, shape (m, 3)
        Where the anchors really are, metres.
    moving_anchors : tuple of int
        The anchors that may be away from where the model says.
    tag_offsets : ndarray, shape (p,)
        Each tag's constant range offset, metres.
    anchor_offsets : ndarray, shape (m,)
        Each anchor's constant range offset, metres.
    bias_offset, bias_amplitude, bias_phase : ndarray, shape (p,)
        The inclinometer biases' constant parts and slow sinusoids' amplitudes (radians)
        and phases (:meth:`inclinometer_bias`).
    links : LinkErrors
        What real links add (:mod:`epp_ros.core.simulation.link_errors`), drawn from a generator of
        its own; ``links.link_offsets`` (p, m) are the tag-anchor pairs' own biases.
    anchor_pair_offsets : ndarray, shape (m, m)
        The anchor-anchor pairs' own biases, symmetric, metres.

    """

    def __init__(self, model, effects=FieldEffects(), rng=None, frame_period=0.1):
        _check_positive('frame_period', frame_period)
        rng = np.random.default_rng(0) if rng is None else rng
        self.model, self.effects, self.rng = model, effects, rng
        self.frame_period = float(frame_period)
        p, m = model.n_sections, model.n_anchors
        self.moving_anchors = self._moving_anchors(effects.moving_anchors)
        moving = np.isin(np.arange(m), self.moving_anchors)
        self.true_anchors = model.anchors + moving[:, None] * rng.normal(
            0.0, effects.anchor_shift, (m, 3))
        self.tag_offsets = rng.normal(0.0, effects.tag_offset, p)
        self.anchor_offsets = rng.normal(0.0, effects.anchor_offset, m)
        bias = effects.inclinometer_bias
        self.bias_offset = rng.normal(0.0, bias / np.sqrt(2.0), p)
        self.bias_amplitude = rng.normal(0.0, bias, p)
        self.bias_phase = rng.uniform(0.0, 2 * np.pi, p)
        # The chains start in their stationary distribution.
        self._nlos = rng.random((p, m)) < effects.nlos_fraction
        self._silent = rng.random(p) < effects.dropout_fraction
        self._stamp = None
        # Last, so that every draw above and every frame's draws stay as they were.
        self._anchor_rng = _child_generator(rng)
        link_rng = _child_generator(rng)
        self.links = LinkErrors(effects, (p, m), link_rng)
        pairs = np.triu(link_rng.normal(0.0, effects.link_offset, (m, m)), 1)
        self.anchor_pair_offsets = pairs + pairs.T

    def same_pump_as(self, other):
        """
        Make this pump ``other``'s: a second recording of the same set-up.

        Its anchors' places, its devices' offsets and its links' constant biases; the
        motion, the noise and the blockages stay this simulator's own.
        """
        self.true_anchors = other.true_anchors.copy()
        self.tag_offsets = other.tag_offsets.copy()
        self.anchor_offsets = other.anchor_offsets.copy()
        self.links.same_links_as(other.links)
        self.anchor_pair_offsets = other.anchor_pair_offsets.copy()

    def _moving_anchors(self, indices):
        m = self.model.n_anchors
        if indices is None:
            base = self.model.base_anchor()
            return tuple(index for index in range(m) if index != base)
        if any(index >= m for index in indices):
            raise ValueError(f'FieldEffects.moving_anchors: the model has anchors 0-{m - 1}, '
                             f'got {list(indices)}')
        return indices

    def anchor_ranges(self, rng=None):
        """
        Return one round of anchor-anchor ranges, as the anchors measure them.

        Anchor i's range to anchor j is the distance between their TRUE positions plus
        ``anchor_offsets[i] + anchor_offsets[j]``, the links' common bias, the pair's own
        and the bias at that range (``range_bias``, ``anchor_pair_offsets``,
        ``bias_curve``), plus noise of the tag ranges' sigma (``sigma + sigma_per_metre
        d``), drawn for each direction independently, clipped at zero.

        Parameters
        ----------
        rng : numpy.random.Generator, optional
            Draws the noise; without one, a stream of the simulator's own, apart from the
            frames' draws so that asking for anchor ranges leaves the frames as they were.

        Returns
        -------
        ndarray, shape (m, m)
            Metres; row i: anchor i's ranges; NaN on the diagonal.

        """
        rng = self._anchor_rng if rng is None else rng
        anchors, effects = self.true_anchors, self.effects
        distances = np.linalg.norm(anchors[:, None] - anchors[None], axis=-1)
        sigma = effects.sigma + effects.sigma_per_metre * distances
        bias = (effects.range_bias + self.anchor_pair_offsets
                + bias_at_range(effects.bias_curve, distances))
        ranges = np.maximum(distances + self.anchor_offsets[:, None] + self.anchor_offsets
                            + bias + sigma * rng.standard_normal(distances.shape), 0.0)
        np.fill_diagonal(ranges, np.nan)
        return ranges

    def inclinometer_bias(self, stamp):
        """Return each inclinometer's bias at ``stamp`` seconds: shape (p,), radians."""
        return self.bias_offset + self.bias_amplitude * np.sin(
            2 * np.pi * stamp / self.effects.bias_period + self.bias_phase)

    def slot_times(self, stamp):
        """
        Return when each tag ranges in the frame of ``stamp``: shape (p,), seconds.

        With TDMA tag k (0-based) of p ranges at ``stamp - T + (k + 1) T / p`` (T the frame
        period; the last tag at ``stamp``), else every tag at ``stamp``.
        """
        p = self.model.n_sections
        if not self.effects.tdma:
            return np.full(p, float(stamp))
        return stamp - self.frame_period + np.arange(1, p + 1) * self.frame_period / p

    def frame(self, motion, stamp):
        """
        Return the next frame, at ``stamp``.

        Parameters
        ----------
        motion : Motion
            How the boom moves.
        stamp : float
            Seconds, later than the previous frame's.

        Returns
        -------
        FieldFrame

        """
        stamp = float(stamp)
        if not np.isfinite(stamp) or (self._stamp is not None and stamp <= self._stamp):
            raise ValueError(f'stamp must be finite and increase, got {stamp!r} after '
                             f'{self._stamp!r}')
        if self._stamp is not None:
            self._step_chains(stamp - self._stamp)
        self._stamp = stamp
        range_stamps = self.slot_times(stamp)
        ranges = self._measure(*self._tags(motion, range_stamps))
        slew_true, pitches_true = motion.angles(stamp)
        pitches, slew = self._angle_sensors(stamp, float(slew_true), pitches_true)
        return FieldFrame(stamp, ranges, range_stamps, pitches, slew,
                          self.model.forward_kinematics(slew_true, pitches_true),
                          float(slew_true), pitches_true, self._nlos.copy(),
                          self._silent.copy())

    def _step_chains(self, elapsed):
        self.links.step(elapsed)
        effects = self.effects
        self._nlos = markov_step(self._nlos, effects.nlos_fraction, effects.nlos_duration,
                                 elapsed, self.rng)
        self._silent = markov_step(self._silent, effects.dropout_fraction,
                                   effects.dropout_duration, elapsed, self.rng)

    def _tags(self, motion, range_stamps):
        """Return each tag (p, 3) and its section's pitch (p,), each at its slot time."""
        p = self.model.n_sections
        slew, pitches = motion.angles(range_stamps)
        tags = self.model.forward_kinematics(slew, pitches)[np.arange(p), np.arange(p)]
        return tags, np.asarray(pitches)[np.arange(p), np.arange(p)]

    def _measure(self, tags, pitches):
        effects, rng = self.effects, self.rng
        true_ranges = np.linalg.norm(tags[:, None, :] - self.true_anchors[None], axis=-1)
        sigma = effects.sigma + effects.sigma_per_metre * true_ranges
        noise = self.links.noise(sigma, rng.standard_normal(true_ranges.shape))
        excess = self._nlos * rng.exponential(effects.nlos_gamma, true_ranges.shape)
        bias = self.links.bias(true_ranges, tags, self.true_anchors, pitches)
        ranges = np.maximum(true_ranges + self.tag_offsets[:, None] + self.anchor_offsets
                            + bias + noise + excess + self.links.outliers(), 0.0)
        missing = rng.random(true_ranges.shape) < effects.link_dropout
        ranges[missing | self._silent[:, None]] = np.nan
        return ranges

    def _angle_sensors(self, stamp, slew_true, pitches_true):
        """Return the inclinometers' pitches (p,) and the encoder's slew, None if absent."""
        effects, rng = self.effects, self.rng
        pitches = slew = None
        if effects.inclinometers:
            pitches = (pitches_true + self.inclinometer_bias(stamp)
                       + effects.pitch_sigma * rng.standard_normal(pitches_true.shape))
        if effects.slew_encoder:
            slew = slew_true + float(rng.uniform(-effects.slew_error, effects.slew_error))
        return pitches, slew


def _child_generator(rng):
    """Return a generator independent of ``rng`` that leaves its draws as they were."""
    try:
        return rng.spawn(1)[0]
    except (AttributeError, TypeError, ValueError):
        # A bit generator without a seed sequence: a jump far ahead instead.
        return np.random.Generator(rng.bit_generator.jumped())


def simulate_field(model, motion, duration, effects=FieldEffects(), rng=None,
                   frame_period=0.1):
    """
    Return the frames of a run, at stamps ``0, T, 2T, ... < duration`` (T: ``frame_period``).

    Parameters
    ----------
    model : BoomModel
        The boom and the anchors as configured.
    motion : Motion
        How the boom moves.
    duration : float
        Seconds.
    effects : FieldEffects
        The field's departures from the configuration.
    rng : numpy.random.Generator, optional
        Draws everything; seeded with 0 without one.
    frame_period : float
        Seconds.

    Returns
    -------
    list of FieldFrame

    """
    if not (np.isfinite(duration) and duration >= 0):
        raise ValueError(f'duration must be finite and >= 0, got {duration!r}')
    simulator = FieldSimulator(model, effects, rng, frame_period)
    count = int(np.ceil(duration / frame_period - 1e-9))
    return [simulator.frame(motion, index * frame_period) for index in range(count)]
