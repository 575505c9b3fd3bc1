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
bare -- a range that names no device: DW1000-ng and DW3000 ranging examples.

Lines::

    Range: 1.23 m	 RX power: -78.32 dBm	 Sampling: 5.00 Hz
    DIST: 1.23 m

The DW1000-ng ``TwoWayRangingInitiator``/``Responder`` examples print ``Range: <m> m``, then
optionally the RX power and the sampling rate; the DW3000 ``ss_twr_initiator`` examples
print ``DIST: <m> m``. Neither names a device: the tag and the anchor come from the source's
``source_tags`` and ``source_anchors`` entries (one source per pair). A ``from:`` before the
range makes it an arduino-dw1000 line, a ``from Anchor`` after it an ``ng_rtls`` one, not
this format. A malformed RX power is one error (the range is still returned).
"""
import math
import re

from epp_ros.uwb.formats.base import (checked_range, decimal, line_text, LineFormat, metres,
                                      ParseResult, RangeRecord)

__all__ = ['parse_bare', 'format_bare', 'FORMAT']

# Bounded repeats keep the search linear in the line length, whatever the line.
_RANGE = re.compile(r'(?<![A-Za-z])(?:Range|DIST):[ \t]*(?P<range>[^\s]{1,64}?)[ \t]*m'
                    r'(?![A-Za-z])', re.ASCII)
_POWER = re.compile(r'RX power:[ \t]*(?P<power>\S{1,64}?)[ \t]*dBm', re.ASCII)


def parse_bare(line):
    """Return the record (anchor and tag None) of a ``Range: ... m`` or ``DIST: ... m`` line."""
    text = line_text(line)
    match = _RANGE.search(text) if text else None
    if match is None or 'from:' in text[:match.start()] or 'from Anchor' in text[match.end():]:
        return None
    value = metres(match.group('range'))
    if value is None:
        return None
    errors, power = 0, None
    if 'RX power:' in text[match.end():]:
        found = _POWER.search(text, match.end())
        power = None if found is None else decimal(found.group('power'))
        errors += power is None
    return ParseResult((RangeRecord(anchor=None, range_m=value, rx_power_dbm=power),), errors)


def format_bare(range_m, rx_power_dbm=None, style='ng'):
    """Return a DW1000-ng (``style='ng'``) or DW3000 (``'dw3000'``) line."""
    value = checked_range(range_m)
    if style == 'dw3000':
        return f'DIST: {value:.2f} m'
    line = f'Range: {value:.2f} m'
    if rx_power_dbm is not None:
        if not math.isfinite(float(rx_power_dbm)):
            raise ValueError(f'RX power must be finite, got {rx_power_dbm!r}')
        line += f'\t RX power: {float(rx_power_dbm):.2f} dBm\t Sampling: 10.00 Hz'
    return line


FORMAT = LineFormat(
    name='bare', parse=parse_bare, names_tag=False, names_anchor=False,
    emit=lambda tag, ranges, cycle: [format_bare(value, cycle.rx_power_dbm)
                                     for value in ranges.values()],
    firmware='DW1000-ng TwoWayRanging examples, DW3000 ss_twr_initiator examples',
    example='Range: 1.23 m\t RX power: -78.32 dBm\t Sampling: 5.00 Hz')
