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
What every line format shares: the records, the descriptor, and small safe conversions.

Standard library only, no ROS. A parser takes one line (with or without its ``\r\n``) and
returns None when the line is not of its format or holds no valid range, else a
:class:`ParseResult`. Parsers never raise, whatever the input. A range is returned only when
it is finite and >= 0; no plausibility limits are applied here. Device ids are returned as
the firmware printed them, stripped and upper-cased; they are compared as numbers later
(:func:`device_number`).
"""
from collections import Counter
from dataclasses import dataclass, field
import math
import re
from typing import Callable

__all__ = ['RangeRecord', 'ParseResult', 'LineFormat', 'Cycle', 'device_number',
           'printed_number']


@dataclass(frozen=True)
class RangeRecord:
    """One range measurement taken from a device line."""

    # device id of the anchor as the line names it, normalised; None in formats that name no
    # device (from the source)
    anchor: str | None
    # metres, finite, >= 0
    range_m: float
    # device id of the tag if the line names it, else None
    tag: str | None = None
    # 'range' (tag-anchor), 'raw' (TREK mr: the same exchange before bias correction) or
    # 'anchor' (anchor-anchor)
    kind: str = 'range'
    rx_power_dbm: float | None = None


@dataclass(frozen=True)
class ParseResult:
    """What one line gave: the valid records and the number of broken pieces skipped."""

    records: tuple              # tuple[RangeRecord, ...]
    errors: int                 # 0 for a clean line


@dataclass(frozen=True)
class Cycle:
    """What an emitter may need besides one tag's ranges (see :attr:`LineFormat.emit`)."""

    sequence: int = 0                           #: ranging cycle number
    anchor_positions: dict = field(default_factory=dict)   #: anchor id -> (x, y, z), m
    rx_power_dbm: float = -80.0


@dataclass(frozen=True)
class LineFormat:
    """
    One device output format: everything the driver, emulator and tools need to know.

    Attributes
    ----------
    name : str
        The ``protocol`` name in ``pump.yaml``.
    parse : callable(str) -> ParseResult or None
        The parser (never raises).
    emit : callable(tag, ranges, cycle) -> list of str
        The lines the device prints for one tag's ranges of one cycle: ``tag`` its id,
        ``ranges`` ``{anchor_id: metres}`` (one entry, ``{None: metres}``, when the format
        names no anchor), ``cycle`` a :class:`Cycle`. Raises ValueError for what the
        format cannot carry.
    firmware : str
        Where the format comes from.
    example : str
        One line as the firmware prints it.
    names_tag : bool
        Whether a line names the tag (else the source's ``source_tags`` entry gives it).
    names_anchor : bool
        Whether a line names the anchor (else the source's ``source_anchors`` entry).
    whole_tag : bool
        Whether one line carries all of one tag's ranges of a ranging cycle (it then also
        says which of that tag's pairs are missing).
    anchor_slots : int or None
        For formats whose anchors are field positions 0..n-1, n; else None.
    id_base : int
        How the firmware prints device ids: 16 (short addresses) or 10 (small numbers).
        Either way ids are compared as the hexadecimal numbers their digits spell, so a
        ``pump.yaml`` gives each id as the firmware prints it (0-9 read the same).
    recognise : callable(str) -> str or None
        For lines of the format that carry no range (positions, HTTP preambles): a label
        to count them under, else None.
    emit_anchors : callable(ranges, cycle) -> list of str, or None
        For formats that report anchor-anchor ranges (records of kind 'anchor'): the lines
        the devices print for one round of them, ``ranges`` ``{(measuring anchor id,
        responding anchor id): metres}`` (pairs the format does not carry are left out),
        ``cycle`` a :class:`Cycle`. None: the format carries none.

    """

    name: str
    parse: Callable
    emit: Callable
    firmware: str
    example: str
    names_tag: bool = True
    names_anchor: bool = True
    whole_tag: bool = False
    anchor_slots: int | None = None
    id_base: int = 16
    recognise: Callable = field(default=lambda line: None)
    emit_anchors: Callable | None = None


# --- device ids -------------------------------------------------------------------------

# Hex digits, or bytes separated by colons as EUIs are printed (``00:01``).
_ID_NUMBER = re.compile(r'(?:0[xX])?([0-9A-Fa-f]{1,16})'
                        r'|([0-9A-Fa-f]{1,2}(?::[0-9A-Fa-f]{1,2}){1,7})', re.ASCII)


def device_number(value):
    """
    Return the number a device id spells in hexadecimal, or None if it is not one.

    Case-insensitive, with or without ``0x``, any zero padding: ``'0B82'``, ``'b82'`` and
    ``'0x0b82'`` are all 0xB82; bytes printed with colons are read as one number, the first
    byte highest (``'0B:82'``). Integers are taken by their decimal digits (``17`` is
    ``'17'``), as JSON bridges print them.
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        value = str(value) if value >= 0 else ''
    if not isinstance(value, str):
        return None
    match = _ID_NUMBER.fullmatch(value.strip())
    if match is None:
        return None
    if match.group(1) is not None:
        return int(match.group(1), 16)
    number = 0
    for byte in match.group(2).split(':'):
        number = number << 8 | int(byte, 16)
    return number


def printed_number(value, maximum=None):
    """
    Return the decimal digits a firmware printing small numbers shows for an id, else ValueError.

    ``'3'``, ``'03'`` and ``'0x3'`` give ``'3'``; an id whose digits are not decimal (``'A'``)
    cannot be printed by such firmware.
    """
    number = device_number(value)
    text = None if number is None else f'{number:X}'
    if text is None or not text.isdigit() or (maximum is not None and int(text) > maximum):
        limit = '' if maximum is None else f' up to {maximum}'
        raise ValueError(f'this format prints ids as decimal numbers{limit}, got {value!r}')
    return text


# --- safe conversions for parsers --------------------------------------------------------

#: Longest number or id text accepted; anything longer is junk.
MAX_FIELD_CHARS = 64

_DECIMAL = re.compile(r'[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?', re.ASCII)
HEX_ID = re.compile(r'[0-9A-Fa-f]{1,16}', re.ASCII)
#: Shell prompts that DWM1001 and other firmware print before output (not noise).
_PROMPT = re.compile(r'^(?:dwm>|nsh>|>)[ \t]*')


def line_text(line):
    """Return the line without surrounding whitespace (and line ending), or None if not a str."""
    return line.strip() if isinstance(line, str) else None


def without_prompt(text):
    """``text`` without a leading shell prompt such as ``dwm> ``."""
    return _PROMPT.sub('', text, count=1)


def junk_errors(text, start):
    """One error if anything but whitespace precedes the start of the line's content."""
    return 1 if text[:start].strip() else 0


def result(records, errors):
    """Return a ParseResult, or None when no record survived."""
    return ParseResult(tuple(records), int(errors)) if records else None


def once_per_anchor(pieces):
    """
    Return the records of (anchor, record) pieces, and how many pieces are errors.

    A broken piece (record None) is an error, and so is every piece of an anchor named
    more than once in a line (a truncated group followed by a repeat): which is right
    cannot be told.

    Parameters
    ----------
    pieces : list of (str or None, RangeRecord or None)
        Each piece's anchor id and record.

    """
    named = Counter(anchor for anchor, _ in pieces if anchor is not None)
    records, errors = [], 0
    for anchor, record in pieces:
        if record is None or named[anchor] > 1:
            errors += 1
        else:
            records.append(record)
    return records, errors


def decimal(text):
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
        if len(text) > MAX_FIELD_CHARS or not _DECIMAL.fullmatch(text):
            return None
        value = float(text)
    else:
        return None
    return value if math.isfinite(value) else None


def metres(value, scale=1.0):
    """Return a valid range in metres from text or number (finite, >= 0, never -0.0), else None."""
    number = decimal(value)
    if number is None or number < 0:
        return None
    value = number * scale
    return value + 0.0 if math.isfinite(value) else None


def normalised_id(value):
    """Return a device id stripped and upper-cased, or None if empty, too long or not one word."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        value = str(value)
    if not isinstance(value, str):
        return None
    text = value.strip().upper()
    if not text or len(text) > MAX_FIELD_CHARS or not text.isprintable():
        return None
    if any(character.isspace() for character in text):
        return None
    return text


# --- checks for emitters -----------------------------------------------------------------

def checked_range(value):
    """``value`` as a float if finite and >= 0, else ValueError (for the formatters)."""
    number = float(value)
    if not math.isfinite(number) or number < 0:
        raise ValueError(f'a range must be finite and >= 0, got {value!r}')
    return number


def checked_id(value, pattern=None):
    """Return a formatter's id as text, ValueError unless it is one normalisable word."""
    text = str(value).strip()
    if normalised_id(text) is None or (pattern and not pattern.fullmatch(text)):
        raise ValueError(f'not a usable device id: {value!r}')
    return text


def slot_of(anchor, slots):
    """Return the field position of an anchor id in a format with ``slots`` positional anchors."""
    return int(printed_number(anchor, slots - 1))
