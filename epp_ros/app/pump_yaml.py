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
Writing a calibration back into a pump.yaml: the values replaced, the file's text kept.

``epp_calibrate --write`` is the user. The file keeps its comments, order and layout where
the values can be replaced in place; otherwise it is dumped again, and either way it must
read back as the same document with the new values (``config.load_pump_config``).
"""
from epp_ros.app.config import ConfigError, pump_config_from_parameters, PUMP_PARAMETERS
import numpy as np
import yaml

__all__ = ['update_pump_yaml', 'CALIBRATED_SETTINGS']


def _yaml_number(value):
    """Return a float as YAML 1.1 and rcl read it back: with a point, no exponent, 1 um."""
    text = f'{float(value):.6f}'.rstrip('0')
    text = text + '0' if text.endswith('.') else text
    return '0.0' if float(text) == 0.0 else text


def _yaml_list(values, column, per_line):
    """Return a flow list of numbers, ``per_line`` a line, continued at ``column + 1``."""
    items = [_yaml_number(v) for v in values]
    rows = [', '.join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return '[' + (',\n' + ' ' * (column + 1)).join(rows) + ']'


#: The estimator's settings a calibration determines (metres, standard deviations): what it
#: leaves unknown of each link's own bias, of the bias common to all and of where the
#: anchors it located stand.
CALIBRATED_SETTINGS = ('link_bias_std', 'common_bias_std', 'anchor_std')


def update_pump_yaml(text, values):
    """
    Return a pump.yaml's text with some pump parameters replaced, all else kept.

    Comments, node settings and the layout stay as written: only the values of the
    ``/**: ros__parameters:`` entries named are rewritten (lists of numbers, three a line
    for ``anchor_positions``); an entry not in the file is added after ``anchor_positions``.
    Should the text not lend itself to that, the document is written anew (comments lost).

    Parameters
    ----------
    text : str
        A pump description as :func:`load_pump_config` reads it.
    values : dict
        Parameter name (of PUMP_PARAMETERS) -> list of numbers, or (of
        :data:`CALIBRATED_SETTINGS`) -> a number >= 0.

    Returns
    -------
    str
        The new text; it parses to the old document with ``values`` (rounded to 1 um)
        replaced.

    Raises
    ------
    ConfigError
        On unknown names, a text without the section, or a result that does not validate.

    """
    unknown = sorted(set(values) - set(PUMP_PARAMETERS) - set(CALIBRATED_SETTINGS))
    if unknown:
        raise ConfigError(f'unknown pump parameter(s) {unknown}')
    for name in set(values) & set(CALIBRATED_SETTINGS):
        if not float(values[name]) >= 0.0 or not np.isfinite(float(values[name])):
            raise ConfigError(f'{name}: must be a finite number >= 0, got {values[name]!r}')
    values = {name: float(_yaml_number(numbers)) if name in CALIBRATED_SETTINGS
              else [float(_yaml_number(v)) for v in numbers]        # as written: to 1 um
              for name, numbers in values.items()}
    try:
        document = yaml.safe_load(text)
        section = document['/**']['ros__parameters']
        section.update(values)
    except (yaml.YAMLError, TypeError, KeyError, AttributeError):
        raise ConfigError("no '/**: ros__parameters:' section to update") from None
    pump_config_from_parameters({name: value for name, value in section.items()
                                 if name in PUMP_PARAMETERS})
    try:
        updated = _edit_in_place(text, values, len(section.get('anchor_names') or ()) or 1)
    except (yaml.YAMLError, ValueError, StopIteration):
        updated = None
    if updated is None or yaml.safe_load(updated) != document:
        updated = yaml.safe_dump(document, default_flow_style=None, sort_keys=False)
    return updated


#: Per-link lists, tag-major: written one tag's links a line.
PER_LINK = ('pair_offsets', 'link_offset_std')


def _edit_in_place(text, values, anchors):
    """Return ``text`` with the values replaced in place (ValueError where it cannot)."""
    top = yaml.compose(text)
    shared = next(v for k, v in top.value if k.value == '/**')
    section = next(v for k, v in shared.value if k.value == 'ros__parameters')
    if not isinstance(section, yaml.MappingNode) or section.flow_style:
        raise ValueError('not a block mapping')
    entries = {key.value: (key, value) for key, value in section.value}
    if 'anchor_positions' not in entries:
        raise ValueError('no anchor_positions to add after')
    edits, added = [], ''       # (start, end, new text); entries added after the positions
    column = entries['anchor_positions'][0].start_mark.column
    for name, numbers in values.items():
        if isinstance(numbers, float):
            written = _yaml_number(numbers)
        else:
            per_line = 3 if name == 'anchor_positions' else anchors if name in PER_LINK \
                else len(numbers) or 1
            start = entries[name][1].start_mark.column if name in entries \
                else column + len(name) + 2
            written = _yaml_list(numbers, start, per_line)
        if name in entries:
            value = entries[name][1]
            edits.append((value.start_mark.index, value.end_mark.index, written))
        else:
            added += f'\n{" " * column}{name}: {written}'
    end = entries['anchor_positions'][1].end_mark.index
    edits.append((end, end, added))
    for start, end, new in sorted(edits, key=lambda edit: edit[0], reverse=True):
        text = text[:start] + new + text[end:]
    return text
