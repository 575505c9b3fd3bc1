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
Range records -> frames: one (p, m) range matrix per ranging cycle.

A cycle opens with its first range and closes when every configured tag-anchor pair has
reported, or ``frame_period`` seconds after it opened, whichever comes first. Ranges from a
tag to another configured tag (a record whose "anchor" is a tag id) are kept as the cycle's
tag-tag ranges; they are optional and never needed to close a cycle. In formats
whose lines carry all of a tag's ranges (``WHOLE_TAG_LINES``) a tag's line also reports its
missing pairs, so the cycle closes as soon as every tag has reported. A pair (or a whole
tag) that reports again before its cycle closed starts the next cycle (the devices have
moved on), so no range that arrived whole is lost. Unused ranges are counted by reason.
Each range keeps its receive time, which ``uwb/ranges`` carries as its age (``contract``).

Anchor-anchor ranges (records of kind 'anchor', e.g. TREK1000 ``ma`` lines) take no part in
the cycles: those of known, different anchors and plausible are kept apart until
:meth:`FrameAssembler.take_anchor_ranges` hands them over as one :class:`AnchorRound`, what
``uwb/anchor_ranges`` carries.
"""
from collections import Counter
from dataclasses import dataclass
import math

import numpy as np

__all__ = ['Frame', 'FrameAssembler', 'AnchorRound', 'MIN_RANGE', 'MAX_RANGE']

#: The plausible ranges, metres, unless min_range and max_range say otherwise: the
#: driver drops others, and epp_calibrate leaves them out of a recording.
MIN_RANGE, MAX_RANGE = 0.05, 200.0


@dataclass
class Frame:
    """One ranging cycle."""

    #: receive time of the newest range (raised by 1 us where needed so that stamps
    #: strictly increase), seconds
    stamp: float
    #: (p, m) metres, NaN where the pair did not report
    ranges: np.ndarray
    #: (p, m) dBm where the device reported it, else NaN
    rx_power: np.ndarray
    #: (p, p) metres from tag row to tag column, NaN where none
    tag_ranges: np.ndarray
    #: (p, m) receive time of each range, seconds on the clock of ``stamp``, NaN where none
    received: np.ndarray
    #: (p, p) receive time of each tag-tag range, seconds, NaN where none
    tag_received: np.ndarray
    #: 1, 2, 3, ... in the order the assembler closed the frames; None: not numbered
    number: int = None


@dataclass
class AnchorRound:
    """Anchor-anchor ranges received together (one device line)."""

    #: receive time of the newest range, seconds
    stamp: float
    #: each range's measuring anchor (index)
    rows: list
    #: each range's responding anchor (index)
    columns: list
    #: metres
    ranges: list


class FrameAssembler:
    """
    Collect range records of a pump into frames.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
    frame_period : float
        Longest cycle, seconds.
    min_range, max_range : float
        Plausible ranges, metres; others are dropped and counted.

    Attributes
    ----------
    dropped : collections.Counter
        Unused records by reason: ``implausible``, ``unknown_tag``, ``unknown_anchor``,
        ``no_tag`` (a line that names no tag on a source configured without one),
        ``no_anchor`` (a line that names no anchor on a source configured without one),
        ``anchor_range`` (anchor-anchor ranges that do not name both anchors) and
        ``raw_range`` (TREK1000 ranges before bias correction, reported again corrected),
        which the estimators do not use. Anchor-anchor ranges of an unknown anchor count as
        ``unknown_anchor``, those of an anchor to itself or out of range as ``implausible``.
    frames : int
        Frames closed so far.
    anchor_ranges : int
        Anchor-anchor ranges kept so far (:meth:`take_anchor_ranges`).

    """

    def __init__(self, config, frame_period=0.1, min_range=MIN_RANGE, max_range=MAX_RANGE):
        if not (frame_period > 0 and 0 <= min_range < max_range):
            raise ValueError('need frame_period > 0 and 0 <= min_range < max_range')
        self.config = config
        self.frame_period = float(frame_period)
        self.min_range, self.max_range = float(min_range), float(max_range)
        self.shape = (len(config.tag_ids), len(config.anchor_ids))
        self.dropped = Counter()
        self.frames = 0
        self.anchor_ranges = 0
        self._anchor_entries = []       # (row, column, metres, stamp) not yet taken
        self._last_stamp = None
        self._reset()

    def _reset(self):
        self._ranges = np.full(self.shape, np.nan)
        self._rx_power = np.full(self.shape, np.nan)
        self._tag_ranges = np.full((self.shape[0], self.shape[0]), np.nan)
        self._received = np.full(self.shape, np.nan)
        self._tag_received = np.full(self._tag_ranges.shape, np.nan)
        self._opened = None
        self._newest = None
        self._tags_done = set()

    def _close(self):
        # Stamps strictly increase: lines of two cycles can arrive in one read.
        stamp = self._newest if self._last_stamp is None else \
            max(self._newest, self._last_stamp + 1e-6)
        self.frames += 1
        frame = Frame(stamp, self._ranges, self._rx_power, self._tag_ranges, self._received,
                      self._tag_received, self.frames)
        self._last_stamp = stamp
        self._reset()
        return frame

    def add(self, record, stamp, source_tag=None, source_anchor=None):
        """
        Add one record received at ``stamp`` (s); return the frames it closed (0 to 2).

        ``source_tag`` and ``source_anchor`` are the device ids of the record's source, used
        when the line names none. Ids compare as numbers (see ``PumpConfig.tag_index``).
        """
        closed = self.poll(stamp)
        if record.kind != 'range':
            self._add_other_kind(record, stamp)
            return closed
        tag = record.tag if record.tag is not None else source_tag
        anchor = record.anchor if record.anchor is not None else source_anchor
        if tag is None or anchor is None:
            self.dropped['no_tag' if tag is None else 'no_anchor'] += 1
        else:
            self._add_pair(record, stamp, tag, anchor, closed)
        return closed

    def _add_other_kind(self, record, stamp):
        """Route a record that is no tag range: anchor-anchor ranges kept apart, others counted."""
        if record.kind == 'anchor':
            self._add_anchor_range(record, stamp)
        else:
            self.dropped[f'{record.kind}_range'] += 1

    def _add_pair(self, record, stamp, tag, anchor, closed):
        """Store a range of a configured pair, or count why it is unused (``dropped``)."""
        row = self.config.tag_index(tag)
        column = self.config.anchor_index(anchor)
        other_tag = self.config.tag_index(anchor) if column is None else None
        if row is None or (column is None and other_tag in (None, row)):
            self.dropped['unknown_tag' if row is None else 'unknown_anchor'] += 1
        elif not self._plausible(record.range_m):
            self.dropped['implausible'] += 1
        elif column is None:
            self._store(record, stamp, True, (row, other_tag), closed)
        else:
            self._store(record, stamp, False, (row, column), closed)

    def _store(self, record, stamp, tag_link, index, closed):
        """Enter a range in the open cycle, closing the cycles it ends so no range is lost."""
        values = self._values(tag_link)
        if not math.isnan(values[index]):
            closed.append(self._close())          # the pair reports again: a new cycle
            values = self._values(tag_link)
        if self._opened is None:
            self._opened = stamp
        values[index] = record.range_m
        (self._tag_received if tag_link else self._received)[index] = stamp
        if record.rx_power_dbm is not None and not tag_link:
            self._rx_power[index] = record.rx_power_dbm
        self._newest = stamp if self._newest is None else max(self._newest, stamp)
        if not np.isnan(self._ranges).any():
            closed.append(self._close())

    def _plausible(self, metres):
        """Whether a range is finite and within [min_range, max_range]."""
        return math.isfinite(metres) and self.min_range <= metres <= self.max_range

    def _add_anchor_range(self, record, stamp):
        """Keep an anchor-anchor record (``tag``: the measuring anchor), or count it dropped."""
        if record.tag is None or record.anchor is None:
            self.dropped['anchor_range'] += 1
            return
        row = self.config.anchor_index(record.tag)
        column = self.config.anchor_index(record.anchor)
        if row is None or column is None:
            self.dropped['unknown_anchor'] += 1
        elif row == column or not self._plausible(record.range_m):
            self.dropped['implausible'] += 1
        else:
            self._anchor_entries.append((row, column, record.range_m, stamp))
            self.anchor_ranges += 1

    def take_anchor_ranges(self):
        """
        Return the anchor-anchor ranges kept since the last call, and forget them.

        Returns
        -------
        AnchorRound or None
            None when there are none.

        """
        if not self._anchor_entries:
            return None
        rows, columns, ranges, stamps = (list(values) for values in zip(*self._anchor_entries))
        self._anchor_entries = []
        return AnchorRound(max(stamps), rows, columns, ranges)

    def _values(self, tag_link):
        """Return the open cycle's tag-tag (p, p) or tag-anchor (p, m) ranges."""
        return self._tag_ranges if tag_link else self._ranges

    def add_line(self, records, stamp, source_tag=None, whole=False, source_anchor=None):
        """
        Add the records of one line; return the frames closed (0 to 2 or so).

        With ``whole`` the line carries all of its tag's ranges this cycle (see
        ``WHOLE_TAG_LINES``): its tag counts as reported, and a tag reporting twice starts
        the next cycle.
        """
        closed = []
        rows = self._line_rows(records, source_tag) if whole else set()
        if not rows.isdisjoint(self._tags_done):
            closed.append(self._close())          # a tag reports again: a new cycle
        for record in records:
            closed += self.add(record, stamp, source_tag, source_anchor)
        if rows and self._opened is not None:
            self._mark_reported(rows, closed)
        return closed

    def _line_rows(self, records, source_tag):
        """Return the rows of the tags whose ranges a whole line carries: those tags report."""
        rows = set()
        for record in records:
            tag = record.tag if record.tag is not None else source_tag
            row = self.config.tag_index(tag) if tag is not None else None
            if record.kind == 'range' and row is not None:
                rows.add(row)
        return rows

    def _mark_reported(self, rows, closed):
        """Mark a whole line's tags reported: the cycle is complete once every tag has."""
        self._tags_done |= rows
        if len(self._tags_done) == self.shape[0]:
            closed.append(self._close())

    def poll(self, now):
        """Close the open cycle if it is ``frame_period`` old; a list of 0 or 1 frame."""
        if self._opened is not None and now - self._opened >= self.frame_period:
            return [self._close()]
        return []
