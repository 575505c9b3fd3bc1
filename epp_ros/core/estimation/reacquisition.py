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
When the estimator doubts its warm start: the re-acquisition policy, apart from the solving.

A warm start follows the boom from frame to frame, and can follow it into the wrong basin.
The policy says when a frame is also solved from scratch (a rejected frame, the first few
in a run and then every tenth, so that garbage does not cost a search per frame; a fit
that calls half a tag's links blocked or leaves it three clear, at most once a period;
while the last search left the frame ambiguous, every frame from the rival it found; for
a method with a state of its own, which gets no such second opinion, a fit a rival
outweighs, spaced as rejected frames are, where the others solve it again, warm, from the
rival position, and follow it once a run of such frames proves it; and its doubted fits
a search beside them, at most once a period, taken where the frame proves it) and when
the warm start is dropped (after ``reset_after_failures`` failures in a row; then the last
fit is only a provisional start, and what it leads to stands only if a search finds it
too). ``PostureEstimator`` does the solving.
"""
import numpy as np

__all__ = ['Reacquisition']


class Reacquisition:
    """
    The re-acquisition state of one estimator: failures in a row and the last search.

    Parameters
    ----------
    reset_after_failures : int
        Failures in a row after which the warm start is dropped.

    """

    #: Seconds between second opinions on fits that call many links blocked.
    SECOND_OPINION_PERIOD = 1.0

    def __init__(self, reset_after_failures=10):
        self.reset_after_failures = reset_after_failures
        self.failures = 0
        self.outweighed_frames = 0      # since the last valid frame: fits a rival outweighed
        self.rival_evidence = 0.0       # nats for the rival's basin, outweighed frames in a row
        self._dropped = False           # the warm start was dropped in this run of failures
        self.in_doubt = False           # the last search found another fit about as likely
        self.rival = None               # that fit, (p, 3), followed from frame to frame
        self._searched = -np.inf        # when the last search was made

    def due_for_search(self):
        """
        Judge whether this rejected frame gets a fresh solve.

        The first few in a run do, then every tenth, so that a stream of garbage does not
        cost a search per frame.
        """
        return _spaced(self.failures + 1)

    def due_for_rival_search(self):
        """
        Count a fit whose frame a joint's rival position outweighs; True when it gets a search.

        The frame is ambiguous, so it is no failure, and a method with a state of its own
        gets no second opinion (``PostureEstimator._reconsider``): a tracker that held a
        wrong fold stayed on it, every frame refused. Spaced as :meth:`due_for_search`'s,
        counted since the last valid frame (so that a stretch of refused frames costs a
        search in ten at most).
        """
        self.outweighed_frames += 1
        return _spaced(self.outweighed_frames)

    def outweighed_by(self, nats):
        """
        Add a frame's evidence for the rival's basin over the warm fit's; return the total.

        ``nats``: how much likelier the frame makes the fit solved from the rival position
        than the warm fit (negative: less likely), or None to start over (a frame not
        outweighed, or the rival taken). A cumulative sum held at zero or above (CUSUM):
        the estimator follows the rival once it reaches the ambiguity odds, so that a
        rival one frame's noise favours by a nat or two is not followed (taken on one
        frame's word, a static tip's other pitch made the estimate flap between the two),
        and one that frame after frame favours is.
        """
        self.rival_evidence = 0.0 if nats is None else max(0.0, self.rival_evidence + nats)
        return self.rival_evidence

    def suspicious(self, nlos_links, ranges, stamp, outlier_links=None):
        """
        Judge whether a fit that explains its frame does so by setting a tag's links aside.

        A warm fit in the wrong basin can fit that way: half of a tag's links or more
        set aside (``nlos_links`` (p, m) of the frame's ``ranges`` (p, m): blocked or
        outliers), or any where it leaves the tag three clear ranges or fewer (three place
        a tag twice, mirrored across their anchors' plane: on a four-anchor pump the
        chain's warm fit slid the last two joints 8-12 m off, one link of each called
        blocked, published at a predicted RMSE of 1.5 m while a search found the truth 13
        nats likelier), or two of a tag's links called outliers (``outlier_links``): an
        outlier is rare and lasts a few frames, and two on one tag say more often that
        the tag is elsewhere (on a seven-anchor pump the chain's warm fit slid joints 4
        and 5 7 m off on real links' biases, three of joint 4's ranges 0.7-1.2 m short
        called outliers frame after frame, published at a predicted RMSE of 0.9 m; the
        truth was 27 nats likelier). Such a fit earns a fresh search, at most once a
        ``SECOND_OPINION_PERIOD``, and every frame while the last search found another
        posture about as likely.
        """
        if self.in_doubt:
            return True
        if stamp - self._searched < self.SECOND_OPINION_PERIOD:
            return False
        flagged = np.sum(nlos_links, axis=1)
        measured = np.sum(np.isfinite(ranges), axis=1)
        half = (flagged >= 2) & (2 * flagged >= measured)
        # Three ranges place a tag twice over (mirrored across their anchors' plane).
        undetermined = (flagged >= 1) & (measured - flagged < 4)
        outlying = np.zeros_like(half) if outlier_links is None else \
            np.sum(outlier_links, axis=1) >= 2
        return bool(np.any(half | undetermined | outlying))

    def searched(self, stamp, ambiguous=None, rival=None):
        """
        Note a search made at ``stamp``.

        ``ambiguous``: whether it left the frame ambiguous; ``rival`` (p, 3): the other fit.
        """
        self._searched = stamp
        self.followed(ambiguous, rival)

    def followed(self, ambiguous=None, rival=None):
        """Note a frame solved from the rival: whether still ambiguous, and the rival now."""
        if ambiguous is not None:           # None: the search failed, the doubt stands
            self.in_doubt = bool(ambiguous)
        self.rival = rival if self.in_doubt else None

    def rival_start(self, stamp):
        """
        Return the rival to solve this doubted frame from, or None when a search is due.

        While in doubt the rival the last search found is followed, warm, from frame to frame
        (what the last frame knew): a search per frame made an ambiguous stream cost 25 good
        frames. A search is made once a ``SECOND_OPINION_PERIOD``, for a rival elsewhere.
        """
        if self.rival is None or stamp - self._searched >= self.SECOND_OPINION_PERIOD:
            return None
        return self.rival

    def failed(self, status):
        """
        Count a rejected frame; True when the warm start must now be dropped.

        A frame that fitted but did not determine the posture (ambiguous, unobservable)
        does not count: its fit is a good start for the next frame. The count goes on past
        the drop, so that searches stay one in ten frames however long the failures last.
        """
        if status in ('ambiguous', 'unobservable'):
            return False
        self.failures += 1
        drop = self.failures >= self.reset_after_failures and not self._dropped
        self._dropped |= drop
        return drop

    def succeeded(self):
        """Start the counts of failures and outweighed fits over (a frame accepted, a new seed)."""
        self.failures, self.outweighed_frames, self._dropped = 0, 0, False


def _spaced(count):
    """Whether the ``count``-th frame of a run gets a search: 1, 2, 4, 8, then every tenth."""
    return count & (count - 1) == 0 or count % 10 == 0
