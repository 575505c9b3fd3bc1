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
haoru -- TREK1000-derived firmware with eight anchors (HaoruTech and its copies).

A line::

    mc f0 00000000 00000000 00000000 00000000 00000630 00000519 000004c2 00000602 0b3e 5f ...

(``...`` is ``0002c3a1 t0:0``, the range time and the token; here anchors 4-7 answered.)

The TREK1000 report line widened to eight ranges, as the firmware's format string
``"mc %02x %08x %08x %08x %08x %08x %08x %08x %08x %04x %02x %08x %c%d:%d"`` prints it (some
builds append the RX power as ``%04x``, ignored): a hex validity mask over eight anchors,
eight ranges in hex millimetres, range count, sequence number, range time, and the token
whose first number is the tag address (see :mod:`epp_ros.uwb.formats.trek`). Anchor ids are
the field positions '0'..'7'; a line may carry only some of them (``mc f0`` ... anchors 4-7).
``mc`` records have kind 'range', ``mr`` kind 'raw'. A line whose fifth field after the mask
is a ``%04x`` range count is a 4-anchor TREK1000 line, not this format.
"""
import re

from epp_ros.uwb.formats.base import LineFormat, printed_number, RangeRecord, result, slot_of
from epp_ros.uwb.formats.trek import decaranging_fields, decaranging_records, range_millimetres

__all__ = ['parse_haoru', 'format_haoru', 'FORMAT']

_SLOTS = 8
_COUNT = re.compile(r'[0-9A-Fa-f]{4}', re.ASCII)
_KINDS = {'mc': 'range', 'mr': 'raw'}


def parse_haoru(line):
    """Return the records of an 8-anchor ``mc``/``mr`` line (see the module docstring)."""
    fields, errors = decaranging_fields(line)
    if fields is None or fields[0] not in _KINDS:
        return None
    if len(fields) > 6 and _COUNT.fullmatch(fields[6]):
        return None                         # a TREK1000 line: four ranges, then the count
    kind = _KINDS[fields[0]]
    records, broken = decaranging_records(
        fields, _SLOTS, lambda index, metres, tag: RangeRecord(str(index), metres, tag, kind))
    return result(records, errors + broken)


def format_haoru(tag, ranges, kind='mc', sequence=0):
    """
    Return an 8-anchor line as a tag prints it, e.g. ``mc 01 000004ec 00000000 ... t1:0``.

    Parameters
    ----------
    tag : str
        The tag's address (decimal digits as printed).
    ranges : dict
        ``{anchor_id: metres}``, anchor ids the field positions '0'..'7'.
    kind : str
        'mc' or 'mr'.
    sequence : int
        Written as the range count and sequence number; the time field is written as zero.

    """
    if kind not in _KINDS:
        raise ValueError(f'kind must be one of {list(_KINDS)}, got {kind!r}')
    millimetres = [0] * _SLOTS
    mask = 0
    for anchor, value in ranges.items():
        slot = slot_of(anchor, _SLOTS)
        millimetres[slot] = range_millimetres(value)
        mask |= 1 << slot
    sequence = int(sequence)
    return ' '.join([kind, f'{mask:02x}', *(f'{value:08x}' for value in millimetres),
                     f'{sequence & 0xFFFF:04x}', f'{sequence & 0xFF:02x}', f'{0:08x}',
                     f't{printed_number(tag)}:0'])


FORMAT = LineFormat(
    name='haoru', parse=parse_haoru, whole_tag=True, anchor_slots=_SLOTS, id_base=10,
    emit=lambda tag, ranges, cycle: [format_haoru(tag, ranges, 'mc', cycle.sequence)],
    firmware='TREK1000-derived 8-anchor firmware (HaoruTech UWB modules and copies)',
    example='mc ff 00000504 000004e4 00000576 000005d8 00000630 00000519 000004c2 00000602 '
            '0b3e 5f 0002c3a1 t0:0')
