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
The device line formats by their 0.1 names: a view of :mod:`epp_ros.uwb.formats`.

Each format lives in its own module under :mod:`epp_ros.uwb.formats`, with its parser, its
formatter and its descriptor; :data:`epp_ros.uwb.formats.FORMATS` is the one registry that
the decoder, the emulator, the configuration and the nodes read. This module keeps the
names earlier code imports: the records, the parse and format functions of the first four
formats, and :data:`PARSERS`/:data:`FORMATTERS` (those four; :data:`ALL_PARSERS` holds
every format's parser).
"""
from epp_ros.uwb.formats import detect_format, FORMATS
from epp_ros.uwb.formats.arduino import format_arduino, parse_arduino
from epp_ros.uwb.formats.base import ParseResult, RangeRecord
from epp_ros.uwb.formats.json_links import format_json, parse_json
from epp_ros.uwb.formats.lec import format_lec, parse_lec
from epp_ros.uwb.formats.trek import format_trek, parse_trek, RAW_BIAS, TREK_ANCHOR_IDS

__all__ = ['RangeRecord', 'ParseResult', 'parse_trek', 'parse_lec', 'parse_arduino',
           'parse_json', 'PARSERS', 'ALL_PARSERS', 'detect_protocol', 'format_trek',
           'format_lec', 'format_arduino', 'format_json', 'FORMATTERS', 'WHOLE_TAG_LINES',
           'TREK_ANCHOR_IDS', 'RAW_BIAS']

#: The parsers of the four formats of release 0.1, by name.
PARSERS = {'trek': parse_trek, 'lec': parse_lec, 'arduino': parse_arduino, 'json': parse_json}
#: Their line formatters (each with its own signature).
FORMATTERS = {'trek': format_trek, 'lec': format_lec, 'arduino': format_arduino,
              'json': format_json}
#: Every format's parser, by name, in the registry's order.
ALL_PARSERS = {name: line_format.parse for name, line_format in FORMATS.items()}
#: Formats in which one line carries all of one tag's ranges of a ranging cycle.
WHOLE_TAG_LINES = frozenset(name for name, line_format in FORMATS.items()
                            if line_format.whole_tag)


def detect_protocol(lines):
    """
    Return the format name whose parser gives records for the most ``lines`` (every format).

    Ties go to the earlier name in the registry; None if no parser reads any line.
    """
    return detect_format(lines)
