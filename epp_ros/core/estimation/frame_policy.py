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
Which range frames reach the estimator, by their stamps: one policy for node and bag tools.

Stamps must increase. A stamp not newer than the last is a repeat or arrived out of order
(ignored), unless it is more than ``backward_jump`` seconds older: then the clock jumped back
(NTP, a restarted driver, a looping bag) and the estimator starts over. A zero, negative or
non-finite stamp is malformed (an unset header, not a time).
"""
import math

__all__ = ['FramePolicy', 'ADMIT', 'OUT_OF_ORDER', 'CLOCK_JUMP', 'MALFORMED']

ADMIT, OUT_OF_ORDER, CLOCK_JUMP, MALFORMED = 'admit', 'out_of_order', 'clock_jump', 'malformed'


class FramePolicy:
    """
    The stamp rules of a stream of range frames.

    Parameters
    ----------
    backward_jump : float
        Seconds: an older stamp by more than this is a clock jump, not disorder.

    """

    def __init__(self, backward_jump=1.0):
        if not backward_jump > 0:
            raise ValueError(f'backward_jump: must be > 0 s, got {backward_jump!r}')
        self.backward_jump = float(backward_jump)
        self.last_stamp = None

    def admit(self, stamp):
        """
        Decide on a frame stamped ``stamp`` (seconds).

        Returns
        -------
        str
            ``ADMIT`` (solve it), ``CLOCK_JUMP`` (solve it from scratch: reset the
            estimator first), ``OUT_OF_ORDER`` or ``MALFORMED`` (ignore it, count it).

        """
        if not (isinstance(stamp, (int, float)) and math.isfinite(stamp) and stamp > 0):
            return MALFORMED
        last, self.last_stamp = self.last_stamp, stamp
        if last is None or stamp > last:
            return ADMIT
        if last - stamp < self.backward_jump:
            self.last_stamp = last
            return OUT_OF_ORDER
        return CLOCK_JUMP
