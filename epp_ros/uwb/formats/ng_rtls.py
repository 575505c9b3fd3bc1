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

r"""
ng_rtls -- DW1000-ng RTLS anchor sketches that name the tag and themselves.

A line::

    Range: 9.04 m\t RX power: -82.30 dBm distance between anchor/tag:40 from Anchor 00:01

Anchors built on the DW1000-ng ``anchorRangeAccept`` examples print the range (metres), the
RX power, the tag's short address as its two bytes run together (``40``, or ``01:01`` in
some sketches) and the last two bytes of their own EUI (``00:01``). Both ids are kept as
printed; bytes with colons compare as the number they spell (``00:01`` is ``0001``,
:func:`~epp_ros.uwb.formats.base.device_number`), so a ``pump.yaml`` may give either.
Without ``from Anchor`` the line is a ``bare`` one, which names no device. A malformed RX
power is one error (the range is still returned).
"""
import math
import re

from epp_ros.uwb.formats.base import (checked_range, decimal, device_number, line_text,
                                      LineFormat, metres, ParseResult, RangeRecord)

__all__ = ['parse_ng_rtls', 'format_ng_rtls', 'FORMAT']

# Bounded repeats keep the search linear in the line length, whatever the line.
_LINE = re.compile(r'(?<![A-Za-z])Range:[ \t]*(?P<range>\S{1,64}?)[ \t]*m(?![A-Za-z])'
                   r'(?P<between>[^\n]{0,200}?)distance between anchor/tag:[ \t]*'
                   r'(?P<tag>[0-9A-Fa-f]{1,4}(?::[0-9A-Fa-f]{1,4}){0,3})[ \t]+from Anchor[ \t]*'
                   r'(?P<anchor>[0-9A-Fa-f]{2}(?::[0-9A-Fa-f]{2}){0,7})(?![0-9A-Za-z:])',
                   re.ASCII)
_POWER = re.compile(r'RX power:[ \t]*(?P<power>\S{1,64}?)[ \t]*dBm', re.ASCII)


def parse_ng_rtls(line):
    """Return the record of a ``Range: ... from Anchor ...`` line, None if it is not one."""
    text = line_text(line)
    match = _LINE.search(text) if text else None
    value = metres(match.group('range')) if match else None
    if value is None:
        return None
    errors, power = 0, None
    if 'RX power:' in match.group('between'):
        found = _POWER.search(match.group('between'))
        power = None if found is None else decimal(found.group('power'))
        errors += power is None
    record = RangeRecord(anchor=match.group('anchor').upper(), range_m=value,
                         tag=match.group('tag').upper(), rx_power_dbm=power)
    return ParseResult((record,), errors)


def format_ng_rtls(tag, anchor, range_m, rx_power_dbm=-80.0):
    """Return a line as the anchor prints it; ids up to four hex digits."""
    numbers = [device_number(device) for device in (tag, anchor)]
    if any(number is None or number > 0xFFFF for number in numbers):
        raise ValueError(f'ids are up to four hex digits, got {tag!r} and {anchor!r}')
    if not math.isfinite(float(rx_power_dbm)):
        raise ValueError(f'RX power must be finite, got {rx_power_dbm!r}')
    tag_number, anchor_number = numbers
    return (f'Range: {checked_range(range_m):.2f} m\t RX power: {float(rx_power_dbm):.2f} dBm '
            f'distance between anchor/tag:{tag_number:X} from Anchor '
            f'{anchor_number >> 8:02X}:{anchor_number & 0xFF:02X}')


FORMAT = LineFormat(
    name='ng_rtls', parse=parse_ng_rtls,
    emit=lambda tag, ranges, cycle: [format_ng_rtls(tag, anchor, value, cycle.rx_power_dbm)
                                     for anchor, value in ranges.items()],
    firmware='DW1000-ng RTLS anchor sketches (anchorRangeAccept, printing the tag and the '
             "anchor's EUI)",
    example='Range: 9.04 m\t RX power: -82.30 dBm distance between anchor/tag:40 from '
            'Anchor 00:01')
