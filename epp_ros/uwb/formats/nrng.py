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
nrng -- Decawave mynewt ``twr_nranges_tdma`` tag (uwb-apps / uwb-core ``nrng``).

A line::

    {"utime": 88307220,"nrng": {"seq": 224,"mask": 3,"rng": ["8.088","1.320"],"uid": ["19","5"]}}

One JSON object per line and ranging slot: ``nrng.rng`` the ranges (metres, strings or
numbers) to the nodes named at the same index of ``nrng.uid`` (ids as printed). The
library's own encoder (``nrng_json.c``) writes the same at the top level, ``{"utime": ...,
"seq": ..., "uid": <tag>, "ouid": [...], "rng": [...]}``, naming the tag in ``uid``; both are
read. A broken pair, or a range or id without its partner, is one error; other JSON objects
the firmware prints (``{"utime": ..., "wcs": [...]}``) are not this format. Text after the
object is one error.
"""
import json

from epp_ros.uwb.formats.base import (checked_range, line_text, LineFormat, metres, normalised_id,
                                      printed_number, RangeRecord, result)
from epp_ros.uwb.formats.json_links import json_object

__all__ = ['parse_nrng', 'format_nrng', 'FORMAT']


def _lists(value):
    """(tag or None, ranges, ids) of either form, or None if the object is not nrng."""
    if not isinstance(value, dict):
        return None
    inner = value.get('nrng')
    if isinstance(inner, dict) and isinstance(inner.get('rng'), list) \
            and isinstance(inner.get('uid'), list):
        return None, inner['rng'], inner['uid']
    if isinstance(value.get('rng'), list) and isinstance(value.get('ouid'), list):
        tag = normalised_id(value.get('uid')) if value.get('uid') is not None else None
        return tag, value['rng'], value['ouid']
    return None


def parse_nrng(line):
    """Return the records of an ``nrng`` JSON line (see the module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    value, errors = json_object(text)
    lists = _lists(value)
    if lists is None:
        return None
    tag, ranges, ids = lists
    errors += abs(len(ranges) - len(ids))
    records = []
    for distance, anchor in zip(ranges, ids):
        anchor, distance = normalised_id(anchor), metres(distance)
        if anchor is None or distance is None:
            errors += 1
        else:
            records.append(RangeRecord(anchor=anchor, range_m=distance, tag=tag))
    return result(records, errors)


def format_nrng(ranges, sequence=0, utime=0):
    """
    Return the tag's line, e.g. ``{"utime": 0,"nrng": {"seq": 0,"mask": 1,"rng": ["8.088"],...``.

    ``ranges`` is ``{node id: metres}``, ids written as given (digits as printed).
    """
    rng = [f'{checked_range(value):.3f}' for value in ranges.values()]
    uid = [str(anchor).strip().upper() for anchor in ranges]
    if any(normalised_id(anchor) is None for anchor in uid):
        raise ValueError(f'not usable node ids: {list(ranges)}')
    inner = {'seq': int(sequence) & 0xFF, 'mask': (1 << len(rng)) - 1, 'rng': rng, 'uid': uid}
    return json.dumps({'utime': int(utime), 'nrng': inner}, separators=(',', ': '))


def _emit(tag, ranges, cycle):
    ids = {printed_number(anchor) if printed_number_ok(anchor) else anchor: value
           for anchor, value in ranges.items()}
    return [format_nrng(ids, cycle.sequence, 1000 * cycle.sequence)]


def printed_number_ok(anchor):
    """Whether an id prints the same as a plain number (no padding to keep)."""
    try:
        return printed_number(anchor) == str(anchor).strip()
    except ValueError:
        return False


FORMAT = LineFormat(
    name='nrng', parse=parse_nrng, emit=_emit, names_tag=False, whole_tag=True,
    firmware='Decawave mynewt uwb-apps twr_nranges_tdma (uwb-core nrng)',
    example='{"utime": 88307220,"nrng": {"seq": 224,"mask": 3,"rng": ["8.088","1.320"],'
            '"uid": ["1946","5199"]}}')
