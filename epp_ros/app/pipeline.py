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
One range frame from message to posture: the steps the live node and ``epp_bag eval`` share.

A ``uwb/ranges`` message passes the stamp rules (``core.frame_policy``), is read into the
pump's links (``PumpConfig.link_frame``), is solved (``PostureEstimator.update``), and is
published only when the estimator judged it valid, as the rigid boom at the estimate's
joint angles. Every frame that goes no further is counted by its reason, under the same
names in the node's ``/diagnostics`` (``frames <key>``) and in the bag tools' reports, so
both decide alike by construction; so are the frames the driver numbered that never came.
No ROS imports: the node passes a message's fields, the bag tools a rosbags message's.
"""
from collections import Counter
from typing import NamedTuple, Optional

from epp_ros.app.contract import frame_number, FrameNumbers
from epp_ros.core.estimation import ADMIT, CLOCK_JUMP, FramePolicy, MALFORMED, OUT_OF_ORDER
import numpy as np

__all__ = ['RangePipeline', 'Step', 'REJECTED']

#: Prefix of the count of frames the estimator refused, by its status.
REJECTED = 'rejected '


class Step(NamedTuple):
    """What became of one frame."""

    #: (p, 3) metres: the posture to publish; None when it may not be.
    joints: Optional[np.ndarray]
    #: The estimator's ``last_diagnostics`` of the frame; None when it never reached it.
    diagnostics: Optional[dict]
    #: The slew (radians) and the pitches ((p,) radians) of ``joints``; None with them.
    angles: Optional[tuple] = None


class RangePipeline:
    """
    The frames of one ``uwb/ranges`` stream through one estimator.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        The pump: its link names and frame.
    estimator : epp_ros.core.PostureEstimator
        Solves the frames; may be replaced between frames (a new method starts cold).

    Attributes
    ----------
    counts : collections.Counter
        ``received``, ``published``; frames going no further by reason: the stamp rules'
        (``out_of_order``, ``malformed``), an unreadable message (``malformed``), refused
        by the estimator (``unsolved``, and ``rejected <status>``); frames that never came,
        from the driver's numbers: ``lost`` on the way, ``before_first`` (published before
        this receiver listened), and ``sender_restarts``; and events: ``clock_jumps``,
        ``unknown_links``, ``cold_restarts``, ``reacquired``.

    """

    def __init__(self, config, estimator):
        self.config = config
        self.estimator = estimator
        self.policy = FramePolicy()
        self.numbers = FrameNumbers()
        self.counts = Counter()

    def step(self, stamp, names, positions, ages=(), slew=None, pitches=None):
        """
        Take one frame: the posture to publish, if any (``counts`` says why not).

        Parameters
        ----------
        stamp : float
            The message's stamp, seconds.
        names, positions, ages : sequence
            The message's ``name``, ``position`` and ``effort`` (``contract.RANGES``).
        slew : float, optional
            The slew encoder's angle at ``stamp``, radians, for methods that fuse it.
        pitches : ndarray, shape (p,), optional
            The inclinometers' at ``stamp``, radians.

        Returns
        -------
        Step

        """
        self.counts['received'] += 1
        self._count_numbers(frame_number(names, positions))
        decision = self.policy.admit(stamp)
        if decision not in (ADMIT, CLOCK_JUMP):
            self.counts[decision] += 1
            return Step(None, None)
        if decision == CLOCK_JUMP:
            self.counts['clock_jumps'] += 1
            self.estimator.reset()
        try:
            links = self.config.link_frame(names, positions, ages)
        except ValueError:
            self.counts['malformed'] += 1
            return Step(None, None)
        self.counts['unknown_links'] += links.unknown
        self.estimator.update(links.ranges, tag_ranges=links.tag_ranges, pitches=pitches,
                              slew=slew, stamp=stamp, range_stamps=links.range_stamps(stamp))
        diagnostics = self.estimator.last_diagnostics
        if not self._judged(diagnostics):
            return Step(None, diagnostics)
        # The boom is rigid: what is published is the boom at the estimate's angles, so
        # that the joint angles and the positions agree exactly (a method that does not
        # hold the lengths, epp1 and epp2, moves by the errors its diagnostics report).
        model = self.estimator.model
        slew, pitches = diagnostics.angles      # as judged: every judged frame has them
        return Step(model.forward_kinematics(slew, pitches), diagnostics, (slew, pitches))

    def _count_numbers(self, number):
        """Count the frames the driver numbered that never came (``contract.FrameNumbers``)."""
        self.numbers.add(number)
        self.counts['lost'] = self.numbers.lost
        self.counts['before_first'] = self.numbers.before_first
        self.counts['sender_restarts'] = self.numbers.restarts

    def _judged(self, diagnostics):
        """Count the estimator's decision on a frame; True when it may be published."""
        self.counts['cold_restarts'] += bool(diagnostics.cold_restart)
        self.counts['reacquired'] += diagnostics.reacquired
        if not diagnostics.valid:
            self.counts['unsolved'] += 1
            self.counts[REJECTED + diagnostics.status] += 1
            return False
        self.counts['published'] += 1
        return True

    def ignored(self):
        """Frames that never reached the estimator, by reason: ``{reason: count}``."""
        return {reason: self.counts[reason] for reason in (OUT_OF_ORDER, MALFORMED)
                if self.counts[reason]}

    def rejected(self):
        """Frames the estimator refused, by its status: ``{status: count}``."""
        return {key[len(REJECTED):]: count for key, count in self.counts.items()
                if key.startswith(REJECTED)}
