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
Every UWB device output format, one descriptor each, in one registry.

A format is one module here that defines ``FORMAT``, a
:class:`~epp_ros.uwb.formats.base.LineFormat`: its parser, its emitter (the emulator's
voice), whether its lines name the tag and the anchor, whether a line carries all of a tag's
ranges, its anchor slots and how it prints ids. Everything else -- the decoder and its
auto-detection, the emulator, the configuration check, the driver, the bag tool -- reads
:data:`FORMATS`, so a new format is a new module, one line below, and its tests.
"""
from epp_ros.uwb.formats import (arduino, bare, haoru, jremington, json_links, lec, les, mauwb,
                                 mauwb_json, ng_rtls, nrng, trek)
from epp_ros.uwb.formats.base import (Cycle, device_number, LineFormat, ParseResult, RangeRecord,
                                      slot_of)

__all__ = ['FORMATS', 'LineFormat', 'Cycle', 'ParseResult', 'RangeRecord', 'device_number',
           'detect_format', 'recognised', 'fits_slots', 'anchor_slot_problem']

#: name -> LineFormat. The order breaks ties in auto-detection: older, stricter formats first.
FORMATS = {module.FORMAT.name: module.FORMAT for module in (
    trek, lec, arduino, json_links, les, haoru, nrng, mauwb, mauwb_json, jremington, ng_rtls,
    bare)}


def detect_format(lines, names=None):
    """
    Return the format among ``names`` (default all) whose parser gives records for most ``lines``.

    Ties go to the earlier name in :data:`FORMATS`; None if no parser reads any line.
    """
    lines = list(lines)
    names = list(FORMATS if names is None else names)
    counts = {name: sum(FORMATS[name].parse(line) is not None for line in lines)
              for name in names}
    best = max(names, key=counts.get)
    return best if counts[best] > 0 else None


def recognised(line, names=None):
    """Return the label under which a format among ``names`` counts a rangeless line, or None."""
    for name in FORMATS if names is None else names:
        label = FORMATS[name].recognise(line)
        if label:
            return label
    return None


def anchor_slot_problem(anchor_ids, protocols):
    """
    Say why sources of these formats cannot carry these anchors, or return None.

    Positional formats (``anchor_slots``) carry an anchor by its field position, so every
    anchor id must be one of the positions 0..slots-1 of the widest such format.

    Parameters
    ----------
    anchor_ids : sequence of str
        The pump's anchor ids.
    protocols : sequence of str
        Each source's format name (unknown names and ``auto`` are not judged).

    Returns
    -------
    str or None

    """
    formats = [FORMATS.get(protocol) for protocol in protocols]
    if not formats or any(f is None or f.anchor_slots is None for f in formats):
        return None
    slots = max(f.anchor_slots for f in formats)
    extra = [a for a in anchor_ids if not fits_slots(a, slots)]
    if not extra:
        return None
    names = '/'.join(sorted({f.name for f in formats}))
    return (f'the {names} format carries at most {slots} anchors per tag (ids 0-{slots - 1}); '
            f'anchors {extra} need another source or another format')


def fits_slots(anchor, slots):
    """Whether an anchor id is one of the field positions 0..slots-1 of a positional format."""
    try:
        slot_of(anchor, slots)
    except ValueError:
        return False
    return True
