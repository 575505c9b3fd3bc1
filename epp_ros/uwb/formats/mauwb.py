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
mauwb -- Makerfabs MaUWB (DW3000 + STM32) AT firmware, automatic range reports.

A line::

    AT+RANGE=tid:1,mask:04,seq:63,range:(0,0,30,0,0,0,0,0),rssi:(0,0,-80.50,0,0,0,0,0)

``tid`` the tag id (decimal), ``mask`` the hex validity mask over the eight anchor slots,
``seq`` the sequence number, ``range`` the eight ranges in centimetres; ``rssi`` and
``ancid`` (the anchor id of each slot, -1 for none; without it the slot number is the anchor
id) are optional. A slot is valid when its mask bit is set (without a mask: when its range
is not 0). A valid slot with a broken range, a broken ``ancid`` entry or a missing ``tid`` is
one error; text before ``AT+RANGE=`` is one error.
"""
import re

from epp_ros.uwb.formats.base import (checked_range, decimal, junk_errors, line_text, LineFormat,
                                      metres, printed_number, RangeRecord, result, slot_of)

__all__ = ['parse_mauwb', 'format_mauwb', 'centimetre_records', 'FORMAT']

SLOTS = 8
_START = re.compile(r'AT\+RANGE=', re.ASCII)
_PART = re.compile(r'([A-Za-z_]{1,16}):(\([^()]{0,600}\)|[^,()]{0,64})', re.ASCII)
_TID = re.compile(r'[0-9]{1,5}', re.ASCII)
_MASK = re.compile(r'(?:0[xX])?([0-9A-Fa-f]{1,4})', re.ASCII)
_ANCID = re.compile(r'-?[0-9]{1,5}', re.ASCII)


def _parts(text):
    """``{key: text}`` of the ``key:value`` parts, lists without their parentheses."""
    return {key: value[1:-1] if value.startswith('(') else value.strip()
            for key, value in _PART.findall(text)}


def centimetre_records(values, tag, mask=None, anchors=None):
    """
    Return (records, errors) of centimetre ranges per slot, as both MaUWB formats give them.

    ``mask`` the validity bits (None: a slot is valid when its value is not 0);
    ``anchors`` the anchor id of each slot (None: the slot number), '' for none.
    """
    records, errors = [], 0
    for slot, value in enumerate(values[:SLOTS]):
        number = decimal(value)
        valid = (mask >> slot & 1) if mask is not None else (number is None or number != 0)
        if not valid:
            continue
        anchor = str(slot) if anchors is None else anchors[slot] if slot < len(anchors) else None
        distance = metres(value, 0.01)
        if distance is None or not anchor:
            errors += anchor != ''
            continue
        records.append(RangeRecord(anchor=anchor, range_m=distance, tag=tag))
    return records, errors


def _anchor_ids(text):
    """Anchor id per slot from an ``ancid`` list ('' for -1, None for a broken entry)."""
    ids = []
    for value in text.split(','):
        value = value.strip()
        ids.append(None if not _ANCID.fullmatch(value) else '' if value.startswith('-')
                   else str(int(value)))
    return ids


def parse_mauwb(line):
    """Return the records of an ``AT+RANGE=`` report (see the module docstring)."""
    text = line_text(line)
    start = _START.search(text) if text else None
    if start is None:
        return None
    errors = junk_errors(text, start.start())
    parts = _parts(text[start.end():])
    if 'range' not in parts:
        return None
    tag = str(int(parts['tid'])) if _TID.fullmatch(parts.get('tid', '')) else None
    mask = _MASK.fullmatch(parts.get('mask', ''))
    anchors = _anchor_ids(parts['ancid']) if 'ancid' in parts else None
    records, broken = centimetre_records(parts['range'].split(','), tag,
                                         int(mask.group(1), 16) if mask else None, anchors)
    return result(records, errors + broken + (tag is None))


def centimetres(ranges):
    """Eight centimetre values and the validity mask of ``{anchor slot id: metres}``."""
    values, mask = [0] * SLOTS, 0
    for anchor, value in ranges.items():
        slot = slot_of(anchor, SLOTS)
        values[slot] = round(checked_range(value) * 100)
        mask |= 1 << slot
    return values, mask


def format_mauwb(tag, ranges, sequence=0, rssi=-80.0):
    """Return a report as the AT firmware prints it (ranges in centimetres, slots '0'..'7')."""
    values, mask = centimetres(ranges)
    power = [f'{rssi:.2f}' if mask >> slot & 1 else '0' for slot in range(SLOTS)]
    return (f'AT+RANGE=tid:{printed_number(tag)},mask:{mask:02x},seq:{int(sequence) & 0xFF},'
            f'range:({",".join(map(str, values))}),rssi:({",".join(power)})')


FORMAT = LineFormat(
    name='mauwb', parse=parse_mauwb, whole_tag=True, anchor_slots=SLOTS, id_base=10,
    emit=lambda tag, ranges, cycle: [format_mauwb(tag, ranges, cycle.sequence,
                                                  cycle.rx_power_dbm)],
    firmware='Makerfabs MaUWB_DW3000 with STM32 AT command firmware (AT+SETRPT=1 reports)',
    example='AT+RANGE=tid:1,mask:04,seq:63,range:(0,0,30,0,0,0,0,0),rssi:(0,0,-80.50,0,0,0,0,0)')
