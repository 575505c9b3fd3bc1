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
The pump description shared by every node and tool (``config/pump.yaml``).

One schema, validated in one place: nodes pass their ROS parameter values to
:func:`pump_config_from_parameters`, plain tools read the YAML with :func:`load_pump_config`.
A bad description raises :class:`ConfigError` with one line naming the field. Writing a
calibration back into the file is ``app.pump_yaml``; a ``uwb/ranges`` message's link names
are the contract's (``app.contract.link_name``).
"""
from array import array
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
import re

from epp_ros.app import contract
from epp_ros.core.model import BoomModel, MAX_RANGE_OFFSET
from epp_ros.uwb.formats import device_number, FORMATS
import numpy as np
import yaml

__all__ = ['ConfigError', 'Source', 'PumpConfig', 'PUMP_PARAMETERS', 'PROTOCOLS',
           'pump_config_from_parameters', 'load_pump_config', 'default_config_path',
           'normalise_device_id', 'device_number', 'listen_address', 'read_parameters']

PROTOCOLS = (*FORMATS, 'auto')
_LISTEN = re.compile(r'tcp-listen://(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+)'
                     r':(?P<port>[0-9]{1,5})')

#: Parameters of the shared pump description: name -> (default, description).
PUMP_PARAMETERS = {
    'frame_id': ('pump_base', 'World frame of ranges and postures (truck frame, z up).'),
    'arm_lengths': ([0.0], 'Section lengths in metres, base outward.'),
    'base': ([0.0, 0.0, 0.0], 'Base pivot [x, y, z] in metres, world frame; with a '
                              'pivot_offset, the slew axis at the pivot height.'),
    'pivot_offset': (0.0, 'Horizontal distance from the slew axis to the boom pivot, '
                          'metres, along the slew direction (0: pivot on the axis).'),
    'tag_names': ([''], 'Tag names, one per joint, base outward.'),
    'tag_ids': ([''], 'Tag device ids as the firmware prints them, as tag_names (compared as '
                      'hexadecimal numbers: 0B82 = B82 = 0xb82).'),
    'anchor_names': ([''], 'Anchor names.'),
    'anchor_ids': ([''], 'Anchor device ids as the firmware prints them (compared as '
                         'hexadecimal numbers).'),
    'anchor_positions': ([0.0], 'Anchor positions, metres, flattened [x0, y0, z0, x1, ...].'),
    'anchor_offsets': ([], 'Constant each anchor adds to its ranges, metres, as anchor_names '
                           '(empty: none); a range measures true + tag + anchor offset.'),
    'tag_offsets': ([], 'Constant each tag adds to its ranges, metres, as tag_names (empty: '
                        'none).'),
    'pair_offsets': ([], "What each tag-anchor link adds beyond its tag's and anchor's "
                         'offsets, metres, tag-major [t0:a0, t0:a1, ...] (empty: none); '
                         'calibrated.'),
    'link_offset_std': ([], "What a calibration leaves unknown of each link's offset (tag + "
                            'anchor + own), metres, as pair_offsets (empty: link_bias_std '
                            'for every link); where given, the estimator weighs each link by '
                            'it instead of link_bias_std. Calibrated.'),
    'body_anchors': ([], 'Anchors on the truck body, by name: they define the truck frame '
                         'and calibration holds them; the others (outriggers) may move with '
                         'each set-up (empty: the first anchor).'),
    'source_ports': ([''], 'Range sources, one each: /dev/tty..., socket://host:port (we '
                           'connect), tcp-listen://address:port (devices connect to us).'),
    'source_protocols': ([''], f'Line protocol of each source: {", ".join(FORMATS)} or '
                               'auto.'),
    'source_tags': ([''], "Tag id on each source for formats that do not name it, else ''."),
    'source_anchors': ([''], 'Anchor id on each source for formats that name no device, else '
                             "'' (all '' when no source needs one)."),
}


class ConfigError(ValueError):
    """A pump description that cannot be used; the message names the field."""


@dataclass(frozen=True)
class Source:
    """One stream of range lines."""

    port: str                   #: device path, socket://host:port or tcp-listen://host:port
    protocol: str               #: one of PROTOCOLS
    tag: str | None = None      #: tag id for formats that do not name it
    anchor: str | None = None   #: anchor id for formats that name no device


@dataclass(frozen=True)
class PumpConfig:
    """A validated pump description."""

    frame_id: str
    arm_lengths: tuple
    base: tuple
    tag_names: tuple
    tag_ids: tuple
    anchor_names: tuple
    anchor_ids: tuple
    anchor_positions: tuple     #: ((x, y, z), ...) per anchor
    sources: tuple              #: (Source, ...)
    pivot_offset: float = 0.0   #: metres from the slew axis to the boom pivot
    anchor_offsets: tuple = None    #: metres each anchor adds to its ranges; None: zeros
    tag_offsets: tuple = None       #: metres each tag adds to its ranges; None: zeros
    body_anchors: tuple = None      #: names of the anchors on the truck body; None: the first
    pair_offsets: tuple = None      #: metres each link adds beyond its devices', tag-major
    #: metres, what is unknown of each link's offset, tag-major; None: ``link_bias_std``
    link_offset_std: tuple = None

    @property
    def body_anchor_indices(self):
        """Return the indices of the anchors on the truck body (the first when not said)."""
        if not self.body_anchors:
            return (0,)
        return tuple(self.anchor_names.index(name) for name in self.body_anchors)

    @property
    def moving_anchor_indices(self):
        """Return the indices of the anchors that may move with each set-up (off the body)."""
        return tuple(j for j in range(len(self.anchor_names))
                     if j not in self.body_anchor_indices)

    def model(self):
        """Return the :class:`BoomModel` of this pump, with its device range offsets."""
        return BoomModel(self.arm_lengths, self.base, self.anchor_positions, self.pivot_offset,
                         self.anchor_offsets, self.tag_offsets, self.pair_offsets)

    def with_link_biases(self, settings):
        """
        Return estimator settings (a dict) with each link's own bias as calibrated.

        Where the description has ``link_offset_std``, it is ``link_bias_std``, one per link
        (rows per tag); otherwise ``settings`` are returned as they are.
        """
        if self.link_offset_std is None:
            return settings
        per_link = np.reshape(self.link_offset_std, (len(self.tag_names), -1))
        return {**settings, 'link_bias_std': per_link}

    @property
    def link_names(self):
        """``"<tag>:<anchor>"`` for every tag-anchor pair, tag-major (row k, column j)."""
        return contract.link_names(self.tag_names, self.anchor_names)

    def tag_link_name(self, row, column):
        """``"<tag>:<tag>"`` of the range measured by tag ``row`` to tag ``column``."""
        return contract.link_name(self.tag_names[row], self.tag_names[column])

    def link_matrices(self, names, values):
        """
        Arrange labelled ranges into the arrays of the estimators.

        Parameters
        ----------
        names : sequence of str
            ``"<tag>:<anchor>"`` and ``"<tag>:<tag>"`` labels, as ``uwb/ranges`` carries
            them, in any order.
        values : sequence of float
            The ranges, metres (NaN for missing).

        Returns
        -------
        ranges : ndarray, shape (p, m)
            Tag-anchor ranges, NaN where a pair is absent.
        tag_ranges : ndarray, shape (p, p)
            Tag-tag ranges, row the measuring tag, NaN where absent (always on the diagonal).
        unknown : int
            Labels that name no configured pair (ignored).

        Raises
        ------
        ValueError
            When ``names`` and ``values`` differ in length.

        """
        frame = self.link_frame(names, values)
        return frame.ranges, frame.tag_ranges, frame.unknown

    def link_frame(self, names, values, ages=None):
        """Arrange a ``uwb/ranges`` message for the estimators (:func:`contract.link_frame`)."""
        return contract.link_frame(names, values, self.tag_names, self.anchor_names, ages)

    def tag_index(self, device_id):
        """
        Joint index (0-based) of a tag device id, or None.

        Ids compare as the hexadecimal numbers they spell: ``'B82'``, ``'0B82'`` and
        ``'0xb82'`` are the same device.
        """
        return self._id_index()[0].get(device_number(device_id))

    def anchor_index(self, device_id):
        """Column of an anchor device id (compared as :meth:`tag_index` does), or None."""
        return self._id_index()[1].get(device_number(device_id))

    def _id_index(self):
        try:
            return self._ids
        except AttributeError:
            ids = tuple({device_number(i): k for k, i in enumerate(values)}
                        for values in (self.tag_ids, self.anchor_ids))
            object.__setattr__(self, '_ids', ids)
            return ids


def normalise_device_id(value):
    """Return a device id as written, without surrounding blanks, upper-case (``0x`` kept out)."""
    text = str(value).strip().upper()
    return text[2:] if text.startswith('0X') and len(text) > 2 else text


def listen_address(port):
    """
    (host, port) of a ``tcp-listen://host:port`` source, None for other ports.

    Raises
    ------
    ConfigError
        For a ``tcp-listen://`` port without an explicit address and a port 1-65535.

    """
    if not port.startswith('tcp-listen://'):
        return None
    match = _LISTEN.fullmatch(port)
    if match is None or not 0 < int(match['port']) < 65536:
        raise ConfigError(f'source_ports: {_short(port)} must be tcp-listen://ADDRESS:PORT '
                          'with an address to bind (e.g. 192.168.4.1, or 0.0.0.0 for every '
                          'interface) and a port 1-65535')
    return match['host'].strip('[]'), int(match['port'])


def _names(values, field):
    names = tuple(str(v).strip() for v in values)
    if not names or any(not n for n in names):
        raise ConfigError(f'{field}: every entry needs a non-empty name, got '
                          f'{_short(list(values))}')
    if any(not re.fullmatch(r'[A-Za-z0-9_]+', n) for n in names):
        raise ConfigError(f'{field}: names may hold letters, digits and _ only, got '
                          f'{_short(list(names))}')
    duplicates = sorted(n for n, times in Counter(names).items() if times > 1)
    if duplicates:
        raise ConfigError(f'{field}: duplicate names {_short(duplicates)}')
    return names


def _device_ids(values, field, count):
    ids = tuple(normalise_device_id(v) for v in values)
    if len(ids) != count:
        raise ConfigError(f'{field}: needs {count} entries (one per name), got {len(ids)}')
    numbers = [device_number(i) for i in ids]
    bad = [v for v, number in zip(values, numbers) if number is None]
    if bad:
        raise ConfigError(f'{field}: device ids must be 1-16 hexadecimal digits, got '
                          f'{_short(bad)}')
    repeated = {n for n, times in Counter(numbers).items() if times > 1}
    duplicates = sorted({i for i, n in zip(ids, numbers) if n in repeated})
    if duplicates:
        raise ConfigError(f'{field}: duplicate device ids {_short(duplicates)} (ids compare as '
                          'numbers: 0B82 = B82)')
    return ids


def _numbers(values, field):
    try:
        return tuple(float(v) for v in values)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f'{field}: must be a list of numbers, got {_short(values)}') from None


def _offsets(values, field, names_field, count):
    """
    Return a list of device range offsets (metres), or None when empty (no offsets).

    Raises
    ------
    ConfigError
        Unless it is one finite number per name of ``names_field``.

    """
    if len(values) == 0:
        return None
    offsets = _numbers(values, field)
    if len(offsets) != count:
        raise ConfigError(f'{field}: needs one offset per entry of {names_field} ({count}) or '
                          f'none, got {len(offsets)}')
    if not all(np.isfinite(offsets)):
        raise ConfigError(f'{field}: must be finite numbers, got {_short(list(values))}')
    if any(abs(v) >= MAX_RANGE_OFFSET for v in offsets):
        raise ConfigError(f'{field}: offsets must be within {MAX_RANGE_OFFSET:g} m, got '
                          f'{_short(list(values))}')
    return offsets


def pump_config_from_parameters(values):
    """
    Validate a pump description given as parameter values (names of PUMP_PARAMETERS).

    Parameters
    ----------
    values : dict
        Missing names take their defaults, which are deliberately unusable.

    Returns
    -------
    PumpConfig

    Raises
    ------
    ConfigError

    """
    unknown = sorted(set(values) - set(PUMP_PARAMETERS))
    if unknown:
        raise ConfigError(f'unknown pump parameter(s) {unknown}')
    get = {name: values.get(name, default) for name, (default, _) in PUMP_PARAMETERS.items()}
    for name, (default, _) in PUMP_PARAMETERS.items():
        # rclpy gives an array parameter set from a message as an array.array.
        if isinstance(default, list) and not isinstance(get[name], (list, tuple, array)):
            raise ConfigError(f'{name}: must be a list, got {_short(get[name])}')
    frame_id = str(get['frame_id']).strip()
    if not frame_id:
        raise ConfigError('frame_id: must not be empty')
    tag_names = _names(get['tag_names'], 'tag_names')
    tag_ids = _device_ids(get['tag_ids'], 'tag_ids', len(tag_names))
    anchor_names = _names(get['anchor_names'], 'anchor_names')
    shared = sorted(set(tag_names) & set(anchor_names))
    if shared:
        raise ConfigError(f'anchor_names: {shared} also name tags; "<tag>:<name>" labels '
                          'must say which')
    anchor_ids = _device_ids(get['anchor_ids'], 'anchor_ids', len(anchor_names))
    flat = _numbers(get['anchor_positions'], 'anchor_positions')
    if len(flat) != 3 * len(anchor_names):
        raise ConfigError(f'anchor_positions: needs 3 numbers per anchor '
                          f'({3 * len(anchor_names)}), got {len(flat)}')
    positions = tuple(tuple(flat[i:i + 3]) for i in range(0, len(flat), 3))
    arm_lengths = _numbers(get['arm_lengths'], 'arm_lengths')
    if len(arm_lengths) != len(tag_names):
        raise ConfigError(f'arm_lengths: needs one length per tag ({len(tag_names)}), '
                          f'got {len(arm_lengths)}')
    base = _numbers(get['base'], 'base')
    try:
        pivot_offset = float(get['pivot_offset'])
    except (TypeError, ValueError, OverflowError):
        shown = _short(get['pivot_offset'])
        raise ConfigError(f'pivot_offset: must be a number, got {shown}') from None
    anchor_offsets = _offsets(get['anchor_offsets'], 'anchor_offsets', 'anchor_names',
                              len(anchor_names))
    tag_offsets = _offsets(get['tag_offsets'], 'tag_offsets', 'tag_names', len(tag_names))
    pair_offsets = _offsets(get['pair_offsets'], 'pair_offsets', 'tag_names x anchor_names',
                            len(tag_names) * len(anchor_names))
    link_offset_std = _offsets(get['link_offset_std'], 'link_offset_std',
                               'tag_names x anchor_names', len(tag_names) * len(anchor_names))
    if link_offset_std is not None and min(link_offset_std) < 0:
        raise ConfigError(f'link_offset_std: must be >= 0, got {_short(list(link_offset_std))}')
    body_anchors = _body_anchors(get['body_anchors'], anchor_names)
    try:
        BoomModel(arm_lengths, base, positions, pivot_offset, anchor_offsets, tag_offsets,
                  pair_offsets)
    except ValueError as exc:
        text = _short(str(exc), 300)
        raise ConfigError(f'anchor_positions: {text}' if text.startswith('anchors ') else text) \
            from None
    sources = _sources(get['source_ports'], get['source_protocols'], get['source_tags'],
                       get['source_anchors'], tag_ids, anchor_ids)
    return PumpConfig(frame_id, arm_lengths, base, tag_names, tag_ids, anchor_names,
                      anchor_ids, positions, sources, pivot_offset, anchor_offsets, tag_offsets,
                      body_anchors, pair_offsets, link_offset_std)


def _body_anchors(values, anchor_names):
    """Return the names of the anchors on the truck body (a tuple), or None when empty."""
    names = tuple(str(value).strip() for value in values)
    if not names:
        return None
    unknown = [name for name in names if name not in anchor_names]
    if unknown:
        raise ConfigError(f'body_anchors: {_short(unknown)} are not in anchor_names')
    if len(set(names)) != len(names):
        raise ConfigError(f'body_anchors: names must be distinct, got {_short(list(names))}')
    return names


def _sources(ports, protocols, tags, anchors, tag_ids, anchor_ids):
    ports = [str(p).strip() for p in ports]
    if not ports or any(not p for p in ports):
        raise ConfigError(f'source_ports: every source needs a port, got {_short(ports)}')
    if len(protocols) != len(ports) or len(tags) != len(ports):
        raise ConfigError(f'source_protocols, source_tags: need one entry per source port '
                          f'({len(ports)}), got {len(protocols)} and {len(tags)}')
    anchors = [str(a).strip() for a in anchors]
    if not any(anchors):
        anchors = [''] * len(ports)
    elif len(anchors) != len(ports):
        raise ConfigError(f'source_anchors: needs one entry per source port ({len(ports)}) '
                          f'or none, got {len(anchors)}')
    sources = tuple(_source(*entry, tag_ids, anchor_ids)
                    for entry in zip(ports, protocols, tags, anchors))
    duplicates = sorted({p for p in ports if ports.count(p) > 1})
    if duplicates:
        raise ConfigError(f'source_ports: duplicate ports {_short(duplicates)}')
    return sources


def _source(port, protocol, tag, anchor, tag_ids, anchor_ids):
    """One validated Source."""
    listen_address(port)
    protocol = str(protocol).strip().lower()
    if protocol not in PROTOCOLS:
        raise ConfigError(f'source_protocols: {_short(protocol)} for {_short(port)} is not one of '
                          f'{list(PROTOCOLS)}')
    tag = _known_id(tag, tag_ids, 'source_tags', 'tag_ids', port)
    anchor = _known_id(anchor, anchor_ids, 'source_anchors', 'anchor_ids', port)
    line_format = FORMATS.get(protocol)
    if line_format is not None and not line_format.names_tag and tag is None:
        raise ConfigError(f'source_tags: {port} speaks {protocol}, which does not name '
                          'the tag: give its tag id')
    if line_format is not None and not line_format.names_anchor and anchor is None:
        raise ConfigError(f'source_anchors: {port} speaks {protocol}, which does not name '
                          'the anchor: give its anchor id')
    return Source(port, protocol, tag, anchor)


def _known_id(value, ids, field, ids_field, port):
    """Return a source's device id (None if empty), ConfigError unless it is one of ``ids``."""
    value = normalise_device_id(value) or None
    if value is not None and device_number(value) not in {device_number(i) for i in ids}:
        raise ConfigError(f'{field}: {_short(value)} for {_short(port)} is not in {ids_field} '
                          f'{_short(list(ids))}')
    return value


def default_config_path():
    """Return the pump description shipped with the package (installed share/ or the checkout)."""
    package = Path(__file__).resolve().parents[1]   # .../epp_ros
    for candidate in (package.parent / 'config' / 'pump.yaml',
                      package.parents[3] / 'share' / 'epp_ros' / 'config' / 'pump.yaml'
                      if len(package.parents) > 3 else None):
        if candidate is not None and candidate.exists():
            return candidate
    raise ConfigError('no config/pump.yaml found next to the package; pass one explicitly')


#: Bytes: a pump description is a few kilobytes; more is not one.
MAX_CONFIG_BYTES = 1 << 20


def _safe_yaml(path):
    """
    Parse a YAML file of bounded size without aliases.

    An alias (``*name``) repeats a node without copying it in the file: a kilobyte of
    nested aliases expands to gigabytes ("billion laughs"). A pump description needs none.

    Raises
    ------
    ConfigError
        On an oversized file or an alias, naming its line.

    """
    size = path.stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise ConfigError(f'{path}: {size} bytes; a pump description is at most '
                          f'{MAX_CONFIG_BYTES} bytes')
    text = path.read_text()
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, yaml.AliasEvent):
            raise ConfigError(f'{path}: line {event.start_mark.line + 1}: YAML aliases '
                              '(*name) are not accepted in a pump description')
    return yaml.safe_load(text)


def _short(value, limit=80):
    """
    Return ``repr(value)`` cut to ``limit`` characters, for one-line error messages.

    Parameters
    ----------
    value : object
        What to show.
    limit : int
        Longest text kept.

    """
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[:limit - 3] + '...'


def load_pump_config(path=None):
    """
    Read and validate a pump description from a ROS parameters YAML file.

    The ``/**`` section holds the description (and node settings, ignored here).
    """
    values = read_parameters(path)
    # The section also holds node settings (baud, method, ...): keep the pump's own.
    return pump_config_from_parameters({name: value for name, value in values.items()
                                        if name in PUMP_PARAMETERS})


def read_parameters(path=None):
    """
    Return the ``/**`` ``ros__parameters`` of a parameters file (default: the packaged one).

    Raises
    ------
    ConfigError
        On a file that cannot be read (or is an alias bomb) or has no such section.

    """
    path = Path(path) if path is not None else default_config_path()
    try:
        document = _safe_yaml(path)
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigError(f'{path}: cannot read: {_short(exc, 200)}') from None
    try:
        values = document['/**']['ros__parameters']
    except (TypeError, KeyError):
        raise ConfigError(f"{path}: no '/**: ros__parameters:' section") from None
    if not isinstance(values, dict):
        raise ConfigError(f"{path}: no '/**: ros__parameters:' section")
    return values
