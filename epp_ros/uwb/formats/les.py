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
les -- Decawave DWM1001 PANS shell command ``les`` (a tag's ranges with anchor positions).

A line::

    022E[7.94,8.03,0.00]=3.38 0C8A[0.00,8.00,2.25]=6.51 le_us=3082 est[2.57,1.98,1.37,56]

Space-separated groups ``<hex id>[x,y,z]=<range>`` (anchor position and range, metres, two
decimals), then the location engine's time ``le_us=<us>`` and its estimate
``est[x,y,z,quality]`` (not returned). The tag is not named (tag None). Each piece is judged
on its own, so a corrupted line keeps its valid groups: a broken group, a broken ``le_us`` or
``est`` part, or any other piece after the first group is one error each; text before the
first group (noise from a reconnect) is one error, a shell prompt (``dwm> ``) none. An anchor
named by more than one group is ambiguous: its groups are all skipped, each an error. A line
with no group but a position (``le_us=... est[...]``, ``lep``'s ``POS,...``) is recognised
and counted as a position.
"""
import re

from epp_ros.uwb.formats.base import (checked_range, decimal, device_number, junk_errors,
                                      line_text, LineFormat, metres, once_per_anchor,
                                      RangeRecord, result, without_prompt)
from epp_ros.uwb.formats.dwm1001 import position_line
from epp_ros.uwb.formats.lec import anchor_xyz

__all__ = ['parse_les', 'format_les', 'FORMAT']

_GROUP = re.compile(r'([0-9A-Fa-f]{1,16})\[([^\[\]]{0,200})\]=([^\s\[\]]{1,64})', re.ASCII)
_GROUP_START = re.compile(r'[0-9A-Fa-f]{1,16}\[', re.ASCII)
_FIRST_GROUP = re.compile(r'(?<![0-9A-Za-z])[0-9A-Fa-f]{1,16}\[', re.ASCII)
_LE_US = re.compile(r'le_us=[0-9]{1,10}', re.ASCII)
_EST = re.compile(r'est\[([^\[\]]{0,200})\]', re.ASCII)


def _group(token):
    """(anchor id or None, record or None) of a ``id[x,y,z]=range`` piece."""
    match = _GROUP.fullmatch(token)
    if match is None:
        return None, None
    anchor = match.group(1).upper()
    xyz = match.group(2).split(',')
    value = metres(match.group(3))
    if len(xyz) != 3 or any(decimal(v) is None for v in xyz) or value is None:
        return anchor, None
    return anchor, RangeRecord(anchor=anchor, range_m=value)


def _est_is_valid(token):
    """Whether an ``est[x,y,z,quality]`` piece is well formed."""
    match = _EST.fullmatch(token)
    values = match.group(1).split(',') if match else []
    return len(values) == 4 and all(decimal(v) is not None for v in values)


def _pieces(text):
    """Return (groups as (anchor, record), errors) of the pieces of a line."""
    first = _FIRST_GROUP.search(text)
    if first is None:
        return [], 0
    errors = junk_errors(text, first.start())
    groups = []
    for token in text[first.start():].split():
        if _GROUP_START.match(token):
            groups.append(_group(token))
        elif token.startswith('le_us='):
            errors += not _LE_US.fullmatch(token)
        elif token.startswith('est['):
            errors += not _est_is_valid(token)
        else:
            errors += 1
    return groups, errors


def parse_les(line):
    """Return the records of a DWM1001 ``les`` line (see the module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    groups, errors = _pieces(without_prompt(text))
    records, broken = once_per_anchor(groups)
    return result(records, errors + broken)


def format_les(ranges, anchors_xyz=None, le_us=0):
    """
    Return a DWM1001 ``les`` line, e.g. ``022E[7.94,8.03,0.00]=3.38 le_us=3082``.

    Parameters
    ----------
    ranges : dict
        ``{anchor_id: metres}``, anchor ids hexadecimal (written as four or more digits).
    anchors_xyz : dict, optional
        ``{anchor_id: (x, y, z)}`` metres; anchors missing here are written at 0, 0, 0.
    le_us : int
        The location engine's time, microseconds.

    """
    parts = []
    known = {device_number(key): xyz for key, xyz in (anchors_xyz or {}).items()}
    for anchor, value in ranges.items():
        number = device_number(anchor)
        if number is None:
            raise ValueError(f'les anchor ids are hexadecimal, got {anchor!r}')
        xyz = ','.join(f'{float(v):.2f}' for v in known.get(number, (0.0, 0.0, 0.0)))
        parts.append(f'{number:04X}[{xyz}]={checked_range(value):.2f}')
    if len(set(parts)) != len(parts) or len({device_number(a) for a in ranges}) != len(parts):
        raise ValueError('an anchor is given twice')
    return ' '.join(parts + [f'le_us={int(le_us)}'])


def _emit(tag, ranges, cycle):
    positions = {anchor: anchor_xyz(cycle, anchor) for anchor in ranges}
    return [format_les(ranges, positions, 2000 + cycle.sequence % 1000)]


FORMAT = LineFormat(
    name='les', parse=parse_les, emit=_emit, names_tag=False, whole_tag=True,
    recognise=position_line,
    firmware='Decawave DWM1001 PANS shell, command les (also lep and listener positions)',
    example='022E[7.94,8.03,0.00]=3.38 0C8A[0.00,8.00,2.25]=6.51 le_us=3082 '
            'est[2.57,1.98,1.37,56]')
