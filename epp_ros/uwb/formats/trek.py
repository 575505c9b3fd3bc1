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
trek -- Decawave TREK1000 / DecaRangeRTLS (EVB1000 firmware, USB virtual COM port).

A line::

    mc 07 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0

Space-separated: the report type (``mc`` bias-corrected tag-anchor ranges, ``mr`` raw
tag-anchor ranges, ``ma`` anchor-anchor ranges); a hex validity mask (bit i set: field i is
a valid range); four ranges in hex millimetres (``%08x``); the range count (``%04x``); the
range sequence number (``%02x``); the range time in ms (``%08x``; an ``mr`` line has the TX
and RX antenna delays ``%04x%04x`` there); and a token ``%c%d:%d``.

The token, as printed by the firmware's main loop (``dw_main.c`` of the TREK1000 source,
e.g. the copy in github.com/gfulco/Trek1000-RTLS, trek1000/src/application/dw_main.c:
``(instance_mode == TAG)?'t':'a', taddr, aaddr``): the letter says which kind of device
printed the line (``t`` a tag, ``a`` an anchor), the first number is the *tag* address and
the second the anchor address, both decimal. So ``a0:0`` is "anchor A0 reports the ranges of
tag 0", and ``t3:1`` is "tag 3 reports its own ranges". Here the first number is the tag id.
For ``mc``/``mr`` field i is the range to anchor i, so the anchor ids are '0'..'3' (the field
position). The firmware prints both for every exchange: ``mc`` records have kind 'range',
``mr`` records kind 'raw', so that a consumer uses the bias-corrected range once. Values
with the top bit set are negative (the firmware prints a signed int with ``%08x``) and count
as errors.

``ma`` lines are printed by the gateway anchor A0 only, with the fixed token ``a0:0``. Its
``instance_anch.c`` stores each anchor-anchor time of flight at index ``(source +
destination) & 3``: field 1 is A0-A1, field 2 is A0-A2, field 3 is A1-A2 (A3 takes no part;
field 0 is unused). A record of kind 'anchor' names the responding anchor in ``anchor`` and
the initiating anchor in ``tag``: field 1 -> (anchor '1', tag '0'), field 2 -> ('2', '0'),
field 3 -> ('2', '1'). A valid bit for field 0 is an error.

A line whose fifth field after the mask is another ``%08x`` range is the 8-anchor variant
(:mod:`epp_ros.uwb.formats.haoru`), not this format. Text before the start of the line
(noise from a reconnect) is one error.
"""
import re

from epp_ros.uwb.formats.base import (checked_range, junk_errors, line_text, LineFormat,
                                      printed_number, RangeRecord, result, slot_of)

__all__ = ['parse_trek', 'format_trek', 'TREK_ANCHOR_IDS', 'FORMAT', 'decaranging_fields',
           'decaranging_records']

_START = re.compile(r'(?<![0-9A-Za-z])m[acr](?=[ \t])', re.ASCII)
_MASK = re.compile(r'[0-9A-Fa-f]{2}', re.ASCII)
RANGE_FIELD = re.compile(r'[0-9A-Fa-f]{8}', re.ASCII)
_TOKEN = re.compile(r'([at])([0-9]{1,10}):([0-9]{1,10})', re.ASCII)
_TAG_ADDRESS = re.compile(r'[0-9]{1,10}', re.ASCII)
_ANCHORS = ('0', '1', '2', '3')
#: Anchor ids the TREK1000 format can carry (its four range fields).
TREK_ANCHOR_IDS = frozenset(_ANCHORS)
#: ``ma`` field -> (initiating anchor, responding anchor).
_ANCHOR_PAIRS = {1: ('0', '1'), 2: ('0', '2'), 3: ('1', '2')}
_KINDS = ('mc', 'mr', 'ma')


def _millimetres(field):
    """Millimetres of a ``%08x`` range field, None if malformed or negative."""
    if not RANGE_FIELD.fullmatch(field):
        return None
    value = int(field, 16)
    return value if value < 2 ** 31 else None


def _token_tag(fields):
    """Tag id (the first number of the ``aT:A``/``tT:A`` token), None if there is no token."""
    for field in fields:
        match = _TOKEN.fullmatch(field)
        if match:
            return str(int(match.group(2)))
    return None


def decaranging_fields(line):
    """
    (fields from the report type on, errors for noise before it), or (None, 0).

    Shared by the TREK1000-derived formats: the fields of a ``mc``/``mr``/``ma`` line whose
    second field is a two-digit hex mask.
    """
    text = line_text(line)
    if text is None:
        return None, 0
    start = _START.search(text)
    if start is None:
        return None, 0
    fields = text[start.start():].split()
    if len(fields) < 2 or not _MASK.fullmatch(fields[1]):
        return None, 0
    return fields, junk_errors(text, start.start())


def decaranging_records(fields, slots, record_of):
    """
    Return (records, errors) of the ``slots`` range fields after the mask.

    ``record_of(index, metres, tag)`` makes the record of valid field ``index`` (None when
    the field has no meaning). A missing token is one error, each broken valid field one.
    """
    mask = int(fields[1], 16)
    tag = _token_tag(fields[2:])
    errors = int(tag is None)
    records = []
    for index in range(slots):
        if not mask >> index & 1:
            continue
        millimetres = _millimetres(fields[2 + index] if len(fields) > 2 + index else '')
        record = None if millimetres is None else record_of(index, millimetres / 1000.0, tag)
        if record is None:
            errors += 1
        else:
            records.append(record)
    return records, errors


def _record(kind, index, metres, tag):
    """Return the record of range field ``index`` of a ``kind`` line, None if it has no meaning."""
    if kind != 'ma':
        return RangeRecord(anchor=_ANCHORS[index], range_m=metres, tag=tag,
                           kind='range' if kind == 'mc' else 'raw')
    pair = _ANCHOR_PAIRS.get(index)
    if pair is None:
        return None
    return RangeRecord(anchor=pair[1], range_m=metres, tag=pair[0], kind='anchor')


def parse_trek(line):
    """Return the records of a TREK1000 ``mc``/``mr``/``ma`` line (see the module docstring)."""
    fields, errors = decaranging_fields(line)
    if fields is None or (len(fields) > 6 and RANGE_FIELD.fullmatch(fields[6])):
        return None
    kind = fields[0]
    records, broken = decaranging_records(
        fields, 4, lambda index, metres, tag: _record(kind, index, metres, tag))
    return result(records, errors + broken)


def format_trek(tag, ranges, kind='mc', sequence=0):
    """
    Return a TREK1000 line as anchor A0 prints it on USB.

    Parameters
    ----------
    tag : str
        Tag address, decimal digits (ignored for ``ma``, whose token is always ``a0:0``).
    ranges : dict
        ``{anchor_id: metres}``; anchor ids '0'..'3' are the range fields. For ``ma`` the
        field is the anchor pair: '1' A0-A1, '2' A0-A2, '3' A1-A2.
    kind : str
        'mc', 'mr' or 'ma'.
    sequence : int
        Written as the range count (low 16 bits) and sequence number (low 8 bits). The time
        field (for ``mr`` the antenna delays) is written as zero.

    Returns
    -------
    str
        E.g. ``mc 07 000004ec 000008ee 0000087e 00000000 0000 00 00000000 a0:0``.

    """
    if kind not in _KINDS:
        raise ValueError(f'kind must be one of {_KINDS}, got {kind!r}')
    allowed = ('1', '2', '3') if kind == 'ma' else _ANCHORS
    millimetres = [0, 0, 0, 0]
    mask = 0
    for anchor, value in ranges.items():
        field = str(anchor).strip()
        if field not in allowed:
            raise ValueError(f'{kind} anchor ids must be one of {allowed}, got {anchor!r}')
        millimetres[int(field)] = range_millimetres(value)
        mask |= 1 << int(field)
    if kind == 'ma':
        token = 'a0:0'
    else:
        tag_text = str(tag).strip()
        if not _TAG_ADDRESS.fullmatch(tag_text):
            raise ValueError(f'a trek tag address is decimal digits, got {tag!r}')
        token = f'a{int(tag_text)}:0'
    sequence = int(sequence)
    return ' '.join([kind, f'{mask:02x}', *(f'{value:08x}' for value in millimetres),
                     f'{sequence & 0xFFFF:04x}', f'{sequence & 0xFF:02x}', f'{0:08x}', token])


def range_millimetres(value):
    """Millimetres of a range for a ``%08x`` field, ValueError if it cannot be written."""
    millimetres = round(checked_range(value) * 1000.0)
    if millimetres >= 2 ** 31:
        raise ValueError(f'range too long for a %08x millimetre field: {value!r}')
    return millimetres


#: Range bias of the emulated raw (``mr``) lines, metres.
RAW_BIAS = 0.25


def _emit(tag, ranges, cycle):
    """Return the ``mr`` (biased) and ``mc`` lines anchor A0 prints for one tag's exchange."""
    fields = {str(slot_of(anchor, 4)): value for anchor, value in ranges.items()}
    tag = printed_number(tag)
    raw = {anchor: value + RAW_BIAS for anchor, value in fields.items()}
    return [format_trek(tag, raw, 'mr', cycle.sequence),
            format_trek(tag, fields, 'mc', cycle.sequence)]


def _emit_anchors(ranges, cycle):
    """
    Return the ``ma`` line anchor A0 prints for one round of anchor-anchor ranges.

    ``ranges`` maps (initiating anchor id, responding anchor id) to metres; the line carries
    the pairs of :data:`_ANCHOR_PAIRS` (A0-A1, A0-A2, A1-A2) found there, none if none is.
    """
    slots = {(slot_of(first, 4), slot_of(second, 4)): value
             for (first, second), value in ranges.items()}
    fields = {str(field): slots[int(first), int(second)]
              for field, (first, second) in _ANCHOR_PAIRS.items()
              if (int(first), int(second)) in slots}
    return [format_trek('0', fields, 'ma', cycle.sequence)] if fields else []


FORMAT = LineFormat(
    name='trek', parse=parse_trek, emit=_emit, emit_anchors=_emit_anchors, whole_tag=True,
    anchor_slots=4, id_base=10,
    firmware='Decawave TREK1000 / EVB1000 DecaRangeRTLS (USB virtual COM port)',
    example='mc 07 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0')
