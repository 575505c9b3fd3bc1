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
arduino -- thotro/arduino-dw1000 ``DW1000Ranging`` examples (``newRange`` callback).

A line::

    from: 1782\t Range: 2.34 m\t RX power: -78.32 dBm

The firmware separates the parts with a tab and a space (any run of spaces and tabs is
accepted); other text may come before ``from`` or after ``m``. ``from`` is the other device's
short address, printed with ``Serial.print(address, HEX)``: without leading zeros (``B82``
for 0x0B82), kept as printed and upper-cased; the range is in metres with two decimals; the
RX power is optional and a malformed one is an error (the range is still returned). The line
does not name the device that printed it (tag None). Makerfabs ESP32 UWB and many sketches
derived from these examples print the same line.
"""
import math
import re

from epp_ros.uwb.formats.base import (checked_id, checked_range, decimal, device_number, line_text,
                                      LineFormat, metres, normalised_id, ParseResult, RangeRecord)

__all__ = ['parse_arduino', 'format_arduino', 'FORMAT']

_ARDUINO_ID = re.compile(r'[0-9A-Za-z:._-]{1,64}', re.ASCII)
# Bounded repeats keep the search linear in the line length, whatever the line.
_ARDUINO_RANGE = re.compile(r'from:[ \t]*(?P<anchor>\S{1,64})[ \t]+Range:[ \t]*'
                            r'(?P<range>\S{1,64}?)[ \t]*m(?![A-Za-z])', re.ASCII)
_ARDUINO_POWER_LABEL = 'RX power:'
_ARDUINO_POWER = re.compile(r'RX power:[ \t]*(?P<power>\S{1,64}?)[ \t]*dBm', re.ASCII)


def parse_arduino(line):
    """Record of an arduino-dw1000 ``from: ... Range: ... m`` line (see the module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    match = _ARDUINO_RANGE.search(text)
    if match is None or not _ARDUINO_ID.fullmatch(match.group('anchor')):
        return None
    value = metres(match.group('range'))
    if value is None:
        return None
    errors = 0
    rx_power = None
    if _ARDUINO_POWER_LABEL in text[match.end():]:
        power = _ARDUINO_POWER.search(text, match.end())
        rx_power = None if power is None else decimal(power.group('power'))
        errors += rx_power is None
    record = RangeRecord(anchor=normalised_id(match.group('anchor')), range_m=value,
                         rx_power_dbm=rx_power)
    return ParseResult((record,), int(errors))


def format_arduino(anchor, range_m, rx_power_dbm=-80.0):
    r"""
    Return an arduino-dw1000 line, e.g. ``from: 1782\t Range: 2.34 m\t RX power: -78.32 dBm``.

    ``rx_power_dbm=None`` leaves the RX power out.
    """
    anchor_id = checked_id(anchor, _ARDUINO_ID)
    line = f'from: {anchor_id}\t Range: {checked_range(range_m):.2f} m'
    if rx_power_dbm is not None:
        power = float(rx_power_dbm)
        if not math.isfinite(power):
            raise ValueError(f'RX power must be finite, got {rx_power_dbm!r}')
        line += f'\t RX power: {power:.2f} dBm'
    return line


def _emit(tag, ranges, cycle):
    """One line per anchor, addresses unpadded as ``Serial.print(address, HEX)`` writes them."""
    return [format_arduino(f'{device_number(anchor):X}', value, cycle.rx_power_dbm)
            for anchor, value in ranges.items()]


FORMAT = LineFormat(
    name='arduino', parse=parse_arduino, emit=_emit, names_tag=False,
    firmware='thotro/arduino-dw1000 DW1000Ranging examples (Makerfabs ESP32 UWB and '
             'derived sketches)',
    example='from: B82\t Range: 2.34 m\t RX power: -78.32 dBm')
