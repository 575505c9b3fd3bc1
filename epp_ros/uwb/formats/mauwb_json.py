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
mauwb_json -- the JSON a Makerfabs MaUWB tag sends over WiFi.

A line::

    {"id":1,"range":[0,0,30,0,0,0,0,0]}

``id`` the tag id (decimal, a number or a string), ``range`` the eight ranges in centimetres
to the anchor slots 0..7, 0 where the anchor did not answer. A broken range is one error;
text after the object is one error.
"""
import json

from epp_ros.uwb.formats.base import line_text, LineFormat, normalised_id, printed_number, result
from epp_ros.uwb.formats.json_links import json_object
from epp_ros.uwb.formats.mauwb import centimetre_records, centimetres, SLOTS

__all__ = ['parse_mauwb_json', 'format_mauwb_json', 'FORMAT']


def parse_mauwb_json(line):
    """Return the records of a ``{"id": ..., "range": [...]}`` line (see the module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    value, errors = json_object(text)
    if not isinstance(value, dict) or not isinstance(value.get('range'), list) \
            or 'links' in value:
        return None
    tag = normalised_id(value.get('id'))
    if tag is None:
        return None
    extra = max(0, len(value['range']) - SLOTS)
    records, broken = centimetre_records(value['range'], tag)
    return result(records, errors + broken + extra)


def format_mauwb_json(tag, ranges):
    """Return the tag's message, e.g. ``{"id":1,"range":[0,0,30,0,0,0,0,0]}``."""
    values, _ = centimetres(ranges)
    return json.dumps({'id': int(printed_number(tag)), 'range': values}, separators=(',', ':'))


FORMAT = LineFormat(
    name='mauwb_json', parse=parse_mauwb_json, whole_tag=True, anchor_slots=SLOTS, id_base=10,
    emit=lambda tag, ranges, cycle: [format_mauwb_json(tag, ranges)],
    firmware='Makerfabs MaUWB ESP32S3 tag examples (JSON over WiFi)',
    example='{"id":1,"range":[0,0,30,0,0,0,0,0]}')
