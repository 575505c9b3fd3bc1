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
What the DWM1001 PANS shell prints besides ranges: positions only.

These are ``lep``, the listener's ``POS,...`` and a ``les`` line whose location engine ran
without ranges.

Shared by the ``lec`` and ``les`` formats, which recognise these lines and count them as
positions, not as garbage.
"""
import re

from epp_ros.uwb.formats.base import decimal, line_text, without_prompt

__all__ = ['position_line']

_POS = re.compile(r'POS,([^\s]{1,200})$', re.ASCII)
_EST = re.compile(r'(?:le_us=[0-9]{1,10}[ \t]+)?est\[([^\[\]]{1,100})\]$', re.ASCII)


def _numbers(text, least):
    """Whether ``text`` holds at least ``least`` comma-separated decimal numbers."""
    return sum(decimal(value) is not None for value in text.split(',')) >= least


def position_line(line):
    """
    ``'position'`` for a DWM1001 line that carries a position and no range, else None.

    ``POS,2.57,1.98,1.37,56`` (``lep``), ``POS,0,D1AA,2.57,1.98,1.37,56,x0A`` (a
    listener), ``le_us=3082 est[2.57,1.98,1.37,56]`` (``les`` without anchors).
    """
    text = line_text(line)
    if text is None:
        return None
    text = without_prompt(text)
    match = _POS.match(text) or _EST.match(text)
    return 'position' if match and _numbers(match.group(1), 3) else None
