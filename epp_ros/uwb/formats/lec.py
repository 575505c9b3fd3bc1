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
lec -- Decawave DWM1001 PANS shell command ``lec`` (CSV location output of a tag).

A line::

    DIST,2,AN0,022E,7.94,8.03,0.00,3.44,AN1,9280,7.95,0.00,0.00,5.68,POS,6.95,5.37,-1.97,52

``DIST,n``, then n groups ``ANi,<hex id>,x,y,z,range`` (anchor position and range in metres,
two decimals), then optionally ``POS,x,y,z,quality`` (the tag's own position, not
returned). The tag is not named (tag None). Groups are found by their ``AN<digits>``
markers, not by offsets, so that the corrupted lines real firmware prints at high rates are
salvaged: a group without exactly its five fields is one error; a declared count unequal to
the number of groups found is one error; a malformed POS part is one error. An anchor id
named by more than one group in a line (a truncated group followed by a repeat) is
ambiguous: its groups are all skipped, each one an error. A shell prompt (``dwm> ``) before
the line is not an error; other text before ``DIST`` is one. Position-only lines (``lep``,
``POS,...``) are recognised and counted as positions.
"""
import math
import re

from epp_ros.uwb.formats.base import (checked_id, checked_range, decimal, device_number, HEX_ID,
                                      junk_errors, line_text, LineFormat, metres,
                                      once_per_anchor, RangeRecord, result, without_prompt)
from epp_ros.uwb.formats.dwm1001 import position_line

__all__ = ['parse_lec', 'format_lec', 'FORMAT']

_LEC_START = re.compile(r'(?<![0-9A-Za-z])DIST,', re.ASCII)
_LEC_MARKER = re.compile(r'AN[0-9]{1,6}', re.ASCII)
_LEC_COUNT = re.compile(r'[0-9]{1,6}', re.ASCII)
_LEC_QUALITY = re.compile(r'[0-9]{1,3}', re.ASCII)


def _lec_is_marker(field):
    """Whether a field starts an anchor group or the position part."""
    return field == 'POS' or bool(_LEC_MARKER.fullmatch(field))


def _lec_declared_count(fields):
    """Return (declared anchor count or None, fields after it)."""
    if fields and _LEC_COUNT.fullmatch(fields[0]):
        return int(fields[0]), fields[1:]
    if fields and not _lec_is_marker(fields[0]):
        return None, fields[1:]          # a garbled count
    return None, fields


def _lec_segments(fields):
    """Split fields at markers: (fields before any marker, [group fields], [POS fields])."""
    head, groups, positions = [], [], []
    current = head
    for field in fields:
        if field == 'POS':
            current = []
            positions.append(current)
        elif _LEC_MARKER.fullmatch(field):
            current = []
            groups.append(current)
        else:
            current.append(field)
    return head, groups, positions


def _lec_group(fields):
    """(anchor id or None, record or None) of the fields after an ``ANi`` marker."""
    anchor = fields[0].upper() if fields and HEX_ID.fullmatch(fields[0]) else None
    if anchor is None or len(fields) != 5:
        return anchor, None
    if any(decimal(value) is None for value in fields[1:4]):
        return anchor, None
    value = metres(fields[4])
    if value is None:
        return anchor, None
    return anchor, RangeRecord(anchor=anchor, range_m=value)


def _lec_position_is_valid(fields):
    """Whether the fields after ``POS`` are x, y, z and a quality factor."""
    return (len(fields) == 4 and all(decimal(value) is not None for value in fields[:3])
            and bool(_LEC_QUALITY.fullmatch(fields[3])))


def parse_lec(line):
    """Return the records of a DWM1001 ``lec`` ``DIST,...`` line (see the module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    text = without_prompt(text)
    start = _LEC_START.search(text)
    if start is None:
        return None
    errors = junk_errors(text, start.start())
    fields = [field.strip() for field in text[start.end():].split(',')]
    while fields and not fields[-1]:
        fields.pop()
    declared, fields = _lec_declared_count(fields)
    errors += declared is None
    head, groups, positions = _lec_segments(fields)
    errors += bool(head)
    errors += declared is not None and declared != len(groups)
    errors += sum(not _lec_position_is_valid(position) for position in positions)
    records, broken = once_per_anchor([_lec_group(group) for group in groups])
    return result(records, errors + broken)


def _xyz(values, what):
    """Three finite floats from ``values`` (a sequence or array), ValueError otherwise."""
    numbers = [float(value) for value in values]
    if len(numbers) != 3 or not all(math.isfinite(value) for value in numbers):
        raise ValueError(f'{what} must be three finite numbers, got {values!r}')
    return numbers


def format_lec(ranges, anchors_xyz=None, position=None):
    """
    Return a DWM1001 ``lec`` line.

    Parameters
    ----------
    ranges : dict
        ``{anchor_id: metres}``, anchor ids hexadecimal text (written upper-case).
    anchors_xyz : dict, optional
        ``{anchor_id: (x, y, z)}`` metres; anchors missing here are written at 0, 0, 0.
    position : sequence, optional
        The tag's ``(x, y, z)`` or ``(x, y, z, quality)``; adds the ``POS`` part (quality
        100 by default).

    Returns
    -------
    str
        E.g. ``DIST,1,AN0,022E,7.94,8.03,0.00,3.44,POS,6.95,5.37,-1.97,52``.

    """
    known = {str(key).strip().upper(): value for key, value in (anchors_xyz or {}).items()}
    parts = ['DIST', str(len(ranges))]
    written = set()
    for index, (anchor, value) in enumerate(ranges.items()):
        anchor_id = checked_id(anchor, HEX_ID).upper()
        if anchor_id in written:
            raise ValueError(f'anchor {anchor!r} given twice')
        written.add(anchor_id)
        xyz = _xyz(known.get(anchor_id, (0.0, 0.0, 0.0)), f'position of anchor {anchor!r}')
        parts += [f'AN{index}', anchor_id, *(f'{value:.2f}' for value in xyz),
                  f'{checked_range(value):.2f}']
    if position is not None:
        values = list(position)
        if len(values) not in (3, 4):
            raise ValueError(f'position must be (x, y, z) or (x, y, z, quality), got {position!r}')
        quality = int(values[3]) if len(values) == 4 else 100
        if not 0 <= quality <= 999:
            raise ValueError(f'position quality must be 0..999, got {quality}')
        parts += ['POS', *(f'{value:.2f}' for value in _xyz(values[:3], 'position')),
                  str(quality)]
    return ','.join(parts)


def anchor_xyz(cycle, anchor):
    """Return the position the emulated firmware reports for an anchor (0, 0, 0 if unknown)."""
    number = device_number(anchor)
    for key, xyz in cycle.anchor_positions.items():
        if device_number(key) == number:
            return xyz
    return (0.0, 0.0, 0.0)


def _emit(tag, ranges, cycle):
    """Return the tag's ``lec`` line (anchor ids in four hex digits, as firmware prints them)."""
    ids = {f'{device_number(anchor):04X}' if device_number(anchor) is not None else anchor:
           value for anchor, value in ranges.items()}
    positions = {key: anchor_xyz(cycle, anchor) for key, anchor in zip(ids, ranges)}
    return [format_lec(ids, positions)]


FORMAT = LineFormat(
    name='lec', parse=parse_lec, emit=_emit, names_tag=False, whole_tag=True,
    recognise=position_line,
    firmware='Decawave DWM1001 PANS shell, command lec (also lep positions)',
    example='DIST,2,AN0,022E,7.94,8.03,0.00,3.44,AN1,9280,7.95,0.00,0.00,5.68,'
            'POS,6.95,5.37,-1.97,52')
