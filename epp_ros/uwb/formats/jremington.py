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
jremington -- jremington/UWB-Indoor-Localization_Arduino tag sketch.

A line::

    1782,2.34

The tag prints, for each range, the anchor's short address with ``Serial.print(address,
HEX)`` (no leading zeros: ``B82``), a comma and the range in metres with two decimals; the
whole line is nothing else, so anything more makes it another format. The tag is not named
(``source_tags``).
"""
import re

from epp_ros.uwb.formats.base import (checked_range, device_number, line_text, LineFormat, metres,
                                      ParseResult, RangeRecord)

__all__ = ['parse_jremington', 'format_jremington', 'FORMAT']

_LINE = re.compile(r'([0-9A-Fa-f]{1,4})[ \t]*,[ \t]*([^,\s]{1,64})', re.ASCII)


def parse_jremington(line):
    """Return the record of a ``<hex address>,<metres>`` line, None if it is not one."""
    text = line_text(line)
    match = _LINE.fullmatch(text) if text else None
    value = metres(match.group(2)) if match else None
    if value is None:
        return None
    return ParseResult((RangeRecord(anchor=match.group(1).upper(), range_m=value),), 0)


def format_jremington(anchor, range_m):
    """Return a line as the tag prints it, e.g. ``B82,2.34``."""
    number = device_number(anchor)
    if number is None or number > 0xFFFF:
        raise ValueError(f'a short address is up to four hex digits, got {anchor!r}')
    return f'{number:X},{checked_range(range_m):.2f}'


FORMAT = LineFormat(
    name='jremington', parse=parse_jremington, names_tag=False,
    emit=lambda tag, ranges, cycle: [format_jremington(a, v) for a, v in ranges.items()],
    firmware='jremington/UWB-Indoor-Localization_Arduino tag sketch (ESP32 + DW1000)',
    example='1782,2.34')
