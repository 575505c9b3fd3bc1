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
Angle sensors next to the UWB ranges: a slew encoder and an inclinometer per section.

They arrive as ``sensor_msgs/JointState`` on their own clock and at their own rate, named by
the configured joint names, in radians: the slew about z from the world x-axis
(counter-clockwise, REP 103), each pitch the section's elevation above the horizontal. A
range frame takes the newest sample whose stamp is within ``max_age`` of its own.
"""
from collections import Counter

import numpy as np

__all__ = ['AngleSamples']


class AngleSamples:
    """
    The newest angle sample, matched to range frames by stamp.

    Parameters
    ----------
    slew_name : str
        Joint name of the slew encoder.
    pitch_names : sequence of str, length p
        Joint names of the inclinometers, section 1 (at the base) outward.
    max_age : float
        Largest stamp difference between a range frame and the angles it takes, seconds.

    Attributes
    ----------
    counts : collections.Counter
        ``messages``, ``malformed`` (names and positions differ in length), ``out_of_order``
        (stamp not newer than the sample held), ``unknown_names`` (names not configured),
        ``frames_with_angles``, ``frames_without_fresh_angles`` (once any angles came).

    """

    def __init__(self, slew_name, pitch_names, max_age):
        names = [str(slew_name)] + [str(name) for name in pitch_names]
        if any(not name.strip() for name in names):
            raise ValueError(f'slew_name, pitch_names: names must not be empty, got {names}')
        if len(set(names)) != len(names):
            raise ValueError(f'slew_name, pitch_names: names must differ, got {names}')
        if not max_age > 0:
            raise ValueError(f'angle_max_age: must be > 0 s, got {max_age}')
        self.max_age = float(max_age)
        self.n_sections = len(names) - 1
        self._index = {name: i for i, name in enumerate(names)}
        self._stamp = None
        self._angles = None             # (p + 1,): slew, then pitches; NaN where not sent
        self.counts = Counter()

    def add(self, stamp, names, positions):
        """
        Take one message's angles, stamped ``stamp`` (s).

        Non-finite values count as not measured. A message that is malformed or not newer
        than the held sample is counted and ignored.
        """
        self.counts['messages'] += 1
        if len(names) != len(positions):
            self.counts['malformed'] += 1
            return
        if self._stamp is not None and stamp <= self._stamp:
            self.counts['out_of_order'] += 1
            return
        angles = np.full(self.n_sections + 1, np.nan)
        for name, value in zip(names, positions):
            index = self._index.get(name)
            if index is None:
                self.counts['unknown_names'] += 1
            elif np.isfinite(value):
                angles[index] = value
        self._stamp, self._angles = stamp, angles

    def at(self, stamp):
        """
        Angles for a range frame stamped ``stamp`` (s).

        Returns
        -------
        slew : float or None
            Radians; None when no fresh sample holds it.
        pitches : ndarray, shape (p,), or None
            Radians, NaN where a section's inclinometer was not sent; None without a
            fresh sample.

        """
        if self._stamp is None:
            return None, None
        if abs(stamp - self._stamp) > self.max_age:
            self.counts['frames_without_fresh_angles'] += 1
            return None, None
        self.counts['frames_with_angles'] += 1
        slew = self._angles[0]
        return (float(slew) if np.isfinite(slew) else None), self._angles[1:].copy()
