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
json -- JSON of WiFi bridges (ESP8266/ESP32 forwarding a tag's ranges).

A line::

    {"tag":"1","links":[{"A":"1782","R":"2.3"}]}

``links`` is required, ``tag`` optional (None when absent). Ids may be strings or integers
(taken by their digits); ``R`` (metres) a string or a number. A broken link is one error; a
``tag`` of the wrong type makes the whole line unusable. Text after the JSON object is one
error. The Makerfabs ESP32 UWB tag (``link.cpp``, ``make_link_json``) writes
``{"links":[{"A":"B82","R":"2.3"}]}`` (``%X``, ``%.1f``) over TCP to a server after an HTTP
request line and headers, with no newline between messages: the request and header lines
are recognised and counted as a preamble (see :mod:`epp_ros.uwb.source` for the framing).
"""
import json
import re

from epp_ros.uwb.formats.base import (checked_id, checked_range, junk_errors, line_text,
                                      LineFormat, metres, normalised_id, RangeRecord, result)

__all__ = ['parse_json', 'format_json', 'json_object', 'http_preamble', 'FORMAT']

#: Where a JSON object may start, and how many such places to try (noise may hold some).
_JSON_START = re.compile(r'\{\s*"')
_JSON_ATTEMPTS = 4


def json_object(text):
    """(first JSON object in ``text``, errors for text around it), or (None, 0)."""
    for attempt, start in enumerate(_JSON_START.finditer(text)):
        if attempt == _JSON_ATTEMPTS:
            break
        try:
            value, end = json.JSONDecoder().raw_decode(text, start.start())
        except Exception:   # malformed, too deep (RecursionError), too long a number...
            continue
        return value, junk_errors(text, start.start()) + bool(text[end:].strip())
    return None, 0


def _json_link(link, tag):
    """Return the record of one ``{"A": ..., "R": ...}`` link, None if broken."""
    if not isinstance(link, dict):
        return None
    anchor = normalised_id(link.get('A'))
    value = metres(link.get('R'))
    if anchor is None or value is None:
        return None
    return RangeRecord(anchor=anchor, range_m=value, tag=tag)


def parse_json(line):
    """Return records of a JSON ``{"tag": ..., "links": [...]}`` line (see module docstring)."""
    text = line_text(line)
    if text is None:
        return None
    value, errors = json_object(text)
    if not isinstance(value, dict) or not isinstance(value.get('links'), list):
        return None
    tag = None
    if value.get('tag') is not None:
        tag = normalised_id(value['tag'])
        if tag is None:
            return None
    records = []
    for link in value['links']:
        record = _json_link(link, tag)
        if record is None:
            errors += 1
        else:
            records.append(record)
    return result(records, errors)


def format_json(tag, ranges):
    """
    Return a JSON line, e.g. ``{"tag":"1","links":[{"A":"1782","R":"2.300"}]}``.

    ``tag=None`` leaves the ``tag`` key out, as some bridges do.
    """
    links = [{'A': checked_id(anchor), 'R': f'{checked_range(value):.3f}'}
             for anchor, value in ranges.items()]
    message = {} if tag is None else {'tag': checked_id(tag)}
    message['links'] = links
    return json.dumps(message, separators=(',', ':'))


_HTTP = re.compile(r'(?:(?:GET|POST|PUT) \S{1,200} HTTP/1\.[01]|(?:Host|Connection|User-Agent'
                   r'|Accept|Content-Type|Content-Length):[ \t]?[^{}]{0,200})$',
                   re.ASCII | re.IGNORECASE)


def http_preamble(line):
    """``'preamble'`` for an HTTP request or header line a WiFi tag writes first, else None."""
    text = line_text(line)
    return 'preamble' if text and _HTTP.match(text) else None


FORMAT = LineFormat(
    name='json', parse=parse_json, whole_tag=True, recognise=http_preamble,
    emit=lambda tag, ranges, cycle: [format_json(tag, ranges)],
    firmware='WiFi bridges (ESP8266/ESP32), Makerfabs ESP32 UWB tag link JSON',
    example='{"tag":"1","links":[{"A":"1782","R":"2.3"}]}')
