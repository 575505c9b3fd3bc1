"""Text line protocols of DW1000 UWB ranging devices: pure parsers and formatters.

Standard library only, no ROS. Every ``parse_*`` function takes one line (with or without
its ``\\r\\n``) and returns None when the line is not of its format or holds no valid range,
else a :class:`ParseResult`: the :class:`RangeRecord` s salvaged and the number of broken
pieces skipped (0 for a clean line). Parsers never raise, whatever the input. A range is
returned only when it is finite and >= 0; no plausibility limits are applied here. Device
ids are normalised: stripped and upper-cased. Each ``format_*`` function writes one line
(without a newline) that its parser reads back to the same records, to the format's
precision; an emulator uses them to impersonate the devices.

trek -- Decawave TREK1000 / DecaRangeRTLS (EVB1000 firmware, USB virtual COM port)::

    mc 07 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0

  Space-separated: the report type (``mc`` bias-corrected tag-anchor ranges, ``mr`` raw
  tag-anchor ranges, ``ma`` anchor-anchor ranges); a hex validity mask (bit i set: field i
  is a valid range); four ranges in hex millimetres (``%08x``); the range count (``%04x``);
  the range sequence number (``%02x``); the range time in ms (``%08x``; an ``mr`` line has
  the TX and RX antenna delays ``%04x%04x`` there); and a token ``%c%d:%d``.

  The token, as printed by the firmware's main loop (``dw_main.c`` of the TREK1000 source,
  e.g. the copy in github.com/gfulco/Trek1000-RTLS, trek1000/src/application/dw_main.c:
  ``(instance_mode == TAG)?'t':'a', taddr, aaddr``): the letter says which kind of device
  printed the line (``t`` a tag, ``a`` an anchor), the first number is the *tag* address
  and the second the anchor address, both decimal. So ``a0:0`` is "anchor A0 reports the
  ranges of tag 0", and ``t3:1`` is "tag 3 reports its own ranges". Here the first number
  is the tag id. For ``mc``/``mr`` field i is the range to anchor i, so the anchor ids are
  '0'..'3' (the field position). The firmware prints both for every exchange: ``mc``
  records have kind 'range', ``mr`` records kind 'raw', so that a consumer uses the
  bias-corrected range once. Values with the top bit set
  are negative (the firmware prints a signed int with ``%08x``) and count as errors.

  ``ma`` lines are printed by the gateway anchor A0 only, with the fixed token ``a0:0``.
  Its ``instance_anch.c`` stores each anchor-anchor time of flight at index
  ``(source + destination) & 3``: field 1 is A0-A1, field 2 is A0-A2, field 3 is A1-A2
  (A3 takes no part; field 0 is unused). A record of kind 'anchor' names the responding
  anchor in ``anchor`` and the initiating anchor in ``tag``: field 1 -> (anchor '1', tag
  '0'), field 2 -> ('2', '0'), field 3 -> ('2', '1'). A valid bit for field 0 is an error.

lec -- Decawave DWM1001 PANS shell command ``lec`` (CSV location output of a tag)::

    DIST,2,AN0,022E,7.94,8.03,0.00,3.44,AN1,9280,7.95,0.00,0.00,5.68,POS,6.95,5.37,-1.97,52

  ``DIST,n``, then n groups ``ANi,<hex id>,x,y,z,range`` (anchor position and range in
  metres, two decimals), then optionally ``POS,x,y,z,quality`` (the tag's own position,
  not returned). The tag is not named (tag None). Groups are found by their ``AN<digits>``
  markers, not by offsets, so that the corrupted lines real firmware prints at high rates
  are salvaged: a group without exactly its five fields is one error; a declared count
  unequal to the number of groups found is one error; a malformed POS part is one error.
  An anchor id named by more than one group in a line (a truncated group followed by a
  repeat) is ambiguous: its groups are all skipped, each one an error.

arduino -- thotro/arduino-dw1000 ``DW1000Ranging`` examples (``newRange`` callback)::

    from: 1782 Range: 2.34 m RX power: -78.32 dBm

  The firmware separates the parts with a tab and a space (any run of spaces and tabs is
  accepted); other text may come before ``from`` or after ``m``. ``from`` is the other
  device's short address (printed in hex; kept as text, upper-cased); the range is in
  metres with two decimals; the RX power is optional and a malformed one is an error (the
  range is still returned). The line does not name the device that printed it (tag None).

json -- JSON lines of WiFi bridges (ESP8266/ESP32 forwarding a tag's ranges)::

    {"tag":"1","links":[{"A":"1782","R":"2.3"}]}

  ``links`` is required, ``tag`` optional (None when absent). Ids may be strings or
  integers; ``R`` (metres) a string or a number. A broken link is one error; a ``tag`` of
  the wrong type makes the whole line unusable. Text after the JSON object is one error.

Text before the start of a trek, lec or json line (noise from a reconnect) is one error.
"""
import json
import math
import re
from collections import Counter
from dataclasses import dataclass

__all__ = ['RangeRecord', 'ParseResult', 'parse_trek', 'parse_lec', 'parse_arduino',
           'parse_json', 'PARSERS', 'detect_protocol', 'format_trek', 'format_lec',
           'format_arduino', 'format_json', 'FORMATTERS']


@dataclass(frozen=True)
class RangeRecord:
    """One range measurement taken from a device line."""

    anchor: str                 # device id of the anchor as the line names it, normalised
    range_m: float              # metres, finite, >= 0
    tag: str | None = None      # device id of the tag if the line names it, else None
    kind: str = 'range'         # 'range' (tag-anchor), 'raw' (TREK mr: the same exchange
                                # before bias correction) or 'anchor' (anchor-anchor)
    rx_power_dbm: float | None = None


@dataclass(frozen=True)
class ParseResult:
    """What one line gave: the valid records and the number of broken pieces skipped."""

    records: tuple              # tuple[RangeRecord, ...]
    errors: int                 # 0 for a clean line


# --- shared helpers ---------------------------------------------------------------------

#: Longest number or id text accepted; anything longer is junk.
_MAX_FIELD_CHARS = 64

_DECIMAL = re.compile(r'[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?', re.ASCII)
_HEX_ID = re.compile(r'[0-9A-Fa-f]{1,16}', re.ASCII)


def _line_text(line):
    """The line without surrounding whitespace (and line ending), or None if not a str."""
    return line.strip() if isinstance(line, str) else None


def _junk_errors(text, start):
    """One error if anything but whitespace precedes the start of the line's content."""
    return 1 if text[:start].strip() else 0


def _result(records, errors):
    """A ParseResult, or None when no record survived."""
    return ParseResult(tuple(records), errors) if records else None


def _decimal(text):
    """Finite float of a plain ASCII decimal number (text or int/float), else None."""
    if isinstance(text, bool):
        return None
    if isinstance(text, (int, float)):
        try:
            value = float(text)
        except OverflowError:
            return None
    elif isinstance(text, str):
        text = text.strip()
        if len(text) > _MAX_FIELD_CHARS or not _DECIMAL.fullmatch(text):
            return None
        value = float(text)
    else:
        return None
    return value if math.isfinite(value) else None


def _range(value):
    """A valid range in metres (finite float >= 0, never -0.0) from text or number, else None."""
    metres = _decimal(value)
    if metres is None or metres < 0:
        return None
    return metres + 0.0


def _normalised_id(value):
    """A device id stripped and upper-cased, or None if empty, too long or not one word."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        value = str(value)
    if not isinstance(value, str):
        return None
    text = value.strip().upper()
    if not text or len(text) > _MAX_FIELD_CHARS or not text.isprintable():
        return None
    if any(character.isspace() for character in text):
        return None
    return text


def _checked_range(metres):
    """``metres`` as a float if finite and >= 0, else ValueError (for the formatters)."""
    value = float(metres)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f'a range must be finite and >= 0, got {metres!r}')
    return value


def _checked_id(value, pattern=None):
    """A formatter's id as text, ValueError unless it is one normalisable word."""
    text = str(value).strip()
    if _normalised_id(text) is None or (pattern and not pattern.fullmatch(text)):
        raise ValueError(f'not a usable device id: {value!r}')
    return text


# --- TREK1000 / DecaRangeRTLS -----------------------------------------------------------

_TREK_START = re.compile(r'(?<![0-9A-Za-z])m[acr](?=[ \t])', re.ASCII)
_TREK_MASK = re.compile(r'[0-9A-Fa-f]{2}', re.ASCII)
_TREK_RANGE = re.compile(r'[0-9A-Fa-f]{8}', re.ASCII)
_TREK_TOKEN = re.compile(r'([at])([0-9]{1,10}):([0-9]{1,10})', re.ASCII)
_TREK_TAG_ADDRESS = re.compile(r'[0-9]{1,10}', re.ASCII)
_TREK_ANCHORS = ('0', '1', '2', '3')
#: Anchor ids the TREK1000 format can carry (its four range fields).
TREK_ANCHOR_IDS = frozenset(_TREK_ANCHORS)
#: ``ma`` field -> (initiating anchor, responding anchor).
_TREK_ANCHOR_PAIRS = {1: ('0', '1'), 2: ('0', '2'), 3: ('1', '2')}
_TREK_KINDS = ('mc', 'mr', 'ma')


def _trek_millimetres(field):
    """Millimetres of a ``%08x`` range field, None if malformed or negative."""
    if not _TREK_RANGE.fullmatch(field):
        return None
    value = int(field, 16)
    return value if value < 2 ** 31 else None


def _trek_tag(fields):
    """Tag id (the first number of the ``aT:A``/``tT:A`` token), None if there is no token."""
    for field in fields:
        match = _TREK_TOKEN.fullmatch(field)
        if match:
            return str(int(match.group(2)))
    return None


def _trek_record(kind, index, metres, tag):
    """The record of range field ``index`` of a ``kind`` line, None if it has no meaning."""
    if kind != 'ma':
        return RangeRecord(anchor=_TREK_ANCHORS[index], range_m=metres, tag=tag,
                           kind='range' if kind == 'mc' else 'raw')
    pair = _TREK_ANCHOR_PAIRS.get(index)
    if pair is None:
        return None
    return RangeRecord(anchor=pair[1], range_m=metres, tag=pair[0], kind='anchor')


def parse_trek(line):
    """Records of a TREK1000 ``mc``/``mr``/``ma`` line (see the module docstring)."""
    text = _line_text(line)
    if text is None:
        return None
    start = _TREK_START.search(text)
    if start is None:
        return None
    fields = text[start.start():].split()
    if len(fields) < 2 or not _TREK_MASK.fullmatch(fields[1]):
        return None
    kind, mask = fields[0], int(fields[1], 16)
    errors = _junk_errors(text, start.start())
    tag = _trek_tag(fields[2:])
    errors += tag is None
    records = []
    for index in range(4):
        if not mask >> index & 1:
            continue
        millimetres = _trek_millimetres(fields[2 + index] if len(fields) > 2 + index else '')
        record = (None if millimetres is None
                  else _trek_record(kind, index, millimetres / 1000.0, tag))
        if record is None:
            errors += 1
        else:
            records.append(record)
    return _result(records, int(errors))


def format_trek(tag, ranges, kind='mc', sequence=0):
    """A TREK1000 line as anchor A0 prints it on USB.

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
    if kind not in _TREK_KINDS:
        raise ValueError(f'kind must be one of {_TREK_KINDS}, got {kind!r}')
    allowed = ('1', '2', '3') if kind == 'ma' else _TREK_ANCHORS
    millimetres = [0, 0, 0, 0]
    mask = 0
    for anchor, metres in ranges.items():
        field = str(anchor).strip()
        if field not in allowed:
            raise ValueError(f'{kind} anchor ids must be one of {allowed}, got {anchor!r}')
        value = round(_checked_range(metres) * 1000.0)
        if value >= 2 ** 31:
            raise ValueError(f'range too long for the trek format: {metres!r}')
        millimetres[int(field)] = value
        mask |= 1 << int(field)
    if kind == 'ma':
        token = 'a0:0'
    else:
        tag_text = str(tag).strip()
        if not _TREK_TAG_ADDRESS.fullmatch(tag_text):
            raise ValueError(f'a trek tag address is decimal digits, got {tag!r}')
        token = f'a{int(tag_text)}:0'
    sequence = int(sequence)
    return ' '.join([kind, f'{mask:02x}', *(f'{value:08x}' for value in millimetres),
                     f'{sequence & 0xFFFF:04x}', f'{sequence & 0xFF:02x}', f'{0:08x}', token])


# --- DWM1001 PANS lec -------------------------------------------------------------------

_LEC_START = re.compile(r'(?<![0-9A-Za-z])DIST,', re.ASCII)
_LEC_MARKER = re.compile(r'AN[0-9]{1,6}', re.ASCII)
_LEC_COUNT = re.compile(r'[0-9]{1,6}', re.ASCII)
_LEC_QUALITY = re.compile(r'[0-9]{1,3}', re.ASCII)


def _lec_is_marker(field):
    """Whether a field starts an anchor group or the position part."""
    return field == 'POS' or bool(_LEC_MARKER.fullmatch(field))


def _lec_declared_count(fields):
    """(declared anchor count or None, fields after it)."""
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
    anchor = fields[0].upper() if fields and _HEX_ID.fullmatch(fields[0]) else None
    if anchor is None or len(fields) != 5:
        return anchor, None
    if any(_decimal(value) is None for value in fields[1:4]):
        return anchor, None
    metres = _range(fields[4])
    if metres is None:
        return anchor, None
    return anchor, RangeRecord(anchor=anchor, range_m=metres)


def _lec_position_is_valid(fields):
    """Whether the fields after ``POS`` are x, y, z and a quality factor."""
    return (len(fields) == 4 and all(_decimal(value) is not None for value in fields[:3])
            and bool(_LEC_QUALITY.fullmatch(fields[3])))


def parse_lec(line):
    """Records of a DWM1001 ``lec`` ``DIST,...`` line (see the module docstring)."""
    text = _line_text(line)
    if text is None:
        return None
    start = _LEC_START.search(text)
    if start is None:
        return None
    errors = _junk_errors(text, start.start())
    fields = [field.strip() for field in text[start.end():].split(',')]
    while fields and not fields[-1]:
        fields.pop()
    declared, fields = _lec_declared_count(fields)
    errors += declared is None
    head, groups, positions = _lec_segments(fields)
    errors += bool(head)
    errors += declared is not None and declared != len(groups)
    errors += sum(not _lec_position_is_valid(position) for position in positions)
    parsed = [_lec_group(group) for group in groups]
    named = Counter(anchor for anchor, _ in parsed if anchor is not None)
    records = []
    for anchor, record in parsed:
        if record is None or named[anchor] > 1:
            errors += 1
        else:
            records.append(record)
    return _result(records, int(errors))


def _xyz(values, what):
    """Three finite floats from ``values`` (a sequence or array), ValueError otherwise."""
    numbers = [float(value) for value in values]
    if len(numbers) != 3 or not all(math.isfinite(value) for value in numbers):
        raise ValueError(f'{what} must be three finite numbers, got {values!r}')
    return numbers


def format_lec(ranges, anchors_xyz=None, position=None):
    """A DWM1001 ``lec`` line.

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
    for index, (anchor, metres) in enumerate(ranges.items()):
        anchor_id = _checked_id(anchor, _HEX_ID).upper()
        if anchor_id in written:
            raise ValueError(f'anchor {anchor!r} given twice')
        written.add(anchor_id)
        xyz = _xyz(known.get(anchor_id, (0.0, 0.0, 0.0)), f'position of anchor {anchor!r}')
        parts += [f'AN{index}', anchor_id, *(f'{value:.2f}' for value in xyz),
                  f'{_checked_range(metres):.2f}']
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


# --- arduino-dw1000 ---------------------------------------------------------------------

_ARDUINO_ID = re.compile(r'[0-9A-Za-z:._-]{1,64}', re.ASCII)
# Bounded repeats keep the search linear in the line length, whatever the line.
_ARDUINO_RANGE = re.compile(r'from:[ \t]*(?P<anchor>\S{1,64})[ \t]+Range:[ \t]*'
                            r'(?P<range>\S{1,64}?)[ \t]*m(?![A-Za-z])', re.ASCII)
_ARDUINO_POWER_LABEL = 'RX power:'
_ARDUINO_POWER = re.compile(r'RX power:[ \t]*(?P<power>\S{1,64}?)[ \t]*dBm', re.ASCII)


def parse_arduino(line):
    """Record of an arduino-dw1000 ``from: ... Range: ... m`` line (see the module docstring)."""
    text = _line_text(line)
    if text is None:
        return None
    match = _ARDUINO_RANGE.search(text)
    if match is None or not _ARDUINO_ID.fullmatch(match.group('anchor')):
        return None
    metres = _range(match.group('range'))
    if metres is None:
        return None
    errors = 0
    rx_power = None
    if _ARDUINO_POWER_LABEL in text[match.end():]:
        power = _ARDUINO_POWER.search(text, match.end())
        rx_power = None if power is None else _decimal(power.group('power'))
        errors += rx_power is None
    record = RangeRecord(anchor=_normalised_id(match.group('anchor')), range_m=metres,
                         rx_power_dbm=rx_power)
    return ParseResult((record,), int(errors))


def format_arduino(anchor, range_m, rx_power_dbm=-80.0):
    """An arduino-dw1000 line, e.g. ``from: 1782\\t Range: 2.34 m\\t RX power: -78.32 dBm``.

    ``rx_power_dbm=None`` leaves the RX power out.
    """
    anchor_id = _checked_id(anchor, _ARDUINO_ID)
    line = f'from: {anchor_id}\t Range: {_checked_range(range_m):.2f} m'
    if rx_power_dbm is not None:
        power = float(rx_power_dbm)
        if not math.isfinite(power):
            raise ValueError(f'RX power must be finite, got {rx_power_dbm!r}')
        line += f'\t RX power: {power:.2f} dBm'
    return line


# --- JSON lines -------------------------------------------------------------------------

#: Where a JSON object may start, and how many such places to try (noise may hold some).
_JSON_START = re.compile(r'\{\s*"')
_JSON_ATTEMPTS = 4


def _json_object(text):
    """(first JSON object in ``text``, errors for text around it), or (None, 0)."""
    for attempt, start in enumerate(_JSON_START.finditer(text)):
        if attempt == _JSON_ATTEMPTS:
            break
        try:
            value, end = json.JSONDecoder().raw_decode(text, start.start())
        except Exception:   # malformed, too deep (RecursionError), too long a number...
            continue
        return value, _junk_errors(text, start.start()) + bool(text[end:].strip())
    return None, 0


def _json_link(link, tag):
    """The record of one ``{"A": ..., "R": ...}`` link, None if broken."""
    if not isinstance(link, dict):
        return None
    anchor = _normalised_id(link.get('A'))
    metres = _range(link.get('R'))
    if anchor is None or metres is None:
        return None
    return RangeRecord(anchor=anchor, range_m=metres, tag=tag)


def parse_json(line):
    """Records of a JSON ``{"tag": ..., "links": [...]}`` line (see the module docstring)."""
    text = _line_text(line)
    if text is None:
        return None
    value, errors = _json_object(text)
    if not isinstance(value, dict) or not isinstance(value.get('links'), list):
        return None
    tag = None
    if value.get('tag') is not None:
        tag = _normalised_id(value['tag'])
        if tag is None:
            return None
    records = []
    for link in value['links']:
        record = _json_link(link, tag)
        if record is None:
            errors += 1
        else:
            records.append(record)
    return _result(records, int(errors))


def format_json(tag, ranges):
    """A JSON line, e.g. ``{"tag":"1","links":[{"A":"1782","R":"2.300"}]}``.

    ``tag=None`` leaves the ``tag`` key out, as some bridges do.
    """
    links = [{'A': _checked_id(anchor), 'R': f'{_checked_range(metres):.3f}'}
             for anchor, metres in ranges.items()]
    message = {} if tag is None else {'tag': _checked_id(tag)}
    message['links'] = links
    return json.dumps(message, separators=(',', ':'))


# --- registry and detection -------------------------------------------------------------

#: Formats in which one line carries all of one tag's ranges of a ranging cycle: the line
#: also says which of that tag's pairs are missing this cycle.
WHOLE_TAG_LINES = frozenset({'trek', 'lec', 'json'})

PARSERS = {'trek': parse_trek, 'lec': parse_lec, 'arduino': parse_arduino, 'json': parse_json}
FORMATTERS = {'trek': format_trek, 'lec': format_lec, 'arduino': format_arduino,
              'json': format_json}


def detect_protocol(lines):
    """The name in PARSERS whose parser gives records for the most ``lines``.

    Ties go to the earlier name in PARSERS; None if no parser reads any line.
    """
    lines = list(lines)
    counts = {name: sum(parser(line) is not None for line in lines)
              for name, parser in PARSERS.items()}
    best = max(PARSERS, key=counts.get)
    return best if counts[best] > 0 else None
