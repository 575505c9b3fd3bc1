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
``dev.py bench fuzz``: generated inputs for every line protocol and every pump configuration field.

Protocols: for each format of :data:`epp_ros.uwb.formats.FORMATS` (and ``auto``), ``inputs``
lines -- random bytes, random text of the format's own characters, truncations, byte flips,
insertions, deletions, duplicated and swapped fields, extreme numbers and splices of real
lines made by the format's emitter -- go through ``LineDecoder(protocol).decode`` and,
when they give records, ``FrameAssembler.add_line``. Nothing may raise.

Configuration: for each field of :data:`epp_ros.app.config.PUMP_PARAMETERS`, ``inputs``
mutated values (wrong types, NaN, inf, huge numbers and lists, nested lists, strings,
empty, negative, duplicates, the shipped value with one element changed) in place of the
shipped one go through :func:`epp_ros.app.config.pump_config_from_parameters`. Only
:class:`~epp_ros.app.config.ConfigError` may come out.

Seeded; no ROS. Every exception that escapes is counted and kept (type, input, traceback).
"""
import dataclasses
import datetime
import random
import time
import traceback

from epp_ros.app.config import (ConfigError, default_config_path, load_pump_config,
                                pump_config_from_parameters, PUMP_PARAMETERS)
from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.formats import Cycle, FORMATS
from epp_ros.uwb.frames import FrameAssembler
import yaml

__all__ = ['fuzz_protocol', 'fuzz_field', 'protocol_seeds', 'FuzzReport', 'run',
           'LINE_MUTATIONS', 'VALUE_MUTATIONS']

#: Distinct escapes (exception type and where it was raised) kept per row; all are counted.
KEEP_ESCAPES = 10
_EXTREME_NUMBERS = ('nan', 'NaN', 'inf', '-inf', 'Infinity', '-1', '-0', '0', '1e309',
                    '-1e309', '1e-400', '9' * 400, '0x10', '1_000', '١٢', '1.2.3', '.', '-',
                    'e5', '', ' ', '0' * 70, 'ffffffffffffffffff', '18446744073709551616')
_SEPARATORS = (',', ' ', '\t', ':', ';', '=', '[', ']', '{', '}', '"', '(', ')')


# --- lines ------------------------------------------------------------------------------

def _format_ids(line_format):
    """(tag id, anchor ids) that a format can print."""
    if line_format.anchor_slots is not None:
        return '1', [str(k) for k in range(min(line_format.anchor_slots, 6))]
    return '1', ['1782', '1783', '1784', '1785']


def protocol_seeds(name, rng, cycles=20):
    """Return real lines of one format: its example and its emitter's lines for random ranges."""
    line_format = FORMATS[name]
    tag, anchors = _format_ids(line_format)
    seeds = [line_format.example]
    positions = {anchor: (float(k), 2.0 * k, 0.5) for k, anchor in enumerate(anchors)}
    for sequence in range(cycles):
        cycle = Cycle(sequence, positions, rng.uniform(-100.0, -60.0))
        if line_format.names_anchor:
            chosen = rng.sample(anchors, rng.randint(1, len(anchors)))
            ranges = {anchor: round(rng.uniform(0.0, 60.0), 3) for anchor in chosen}
        else:
            ranges = {None: round(rng.uniform(0.0, 60.0), 3)}
        try:
            seeds += line_format.emit(tag, ranges, cycle)
        except ValueError:
            continue
    return seeds


def _assembler_for(name):
    """Return (assembler, source tag, source anchor) fitting the ids of the format's seeds."""
    config = load_pump_config()
    tag, anchors = _format_ids(FORMATS[name])
    anchor_ids = tuple((anchors * 2)[:len(config.anchor_ids)])
    if len(set(anchor_ids)) < len(anchor_ids):
        anchor_ids = tuple(str(k) for k in range(len(config.anchor_ids)))
    config = dataclasses.replace(config, anchor_ids=anchor_ids)
    return FrameAssembler(config), tag, anchor_ids[0]


def _random_bytes(rng, seed):
    return bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 200))).decode(
        'utf-8', errors='replace')


def _random_latin1(rng, seed):
    return bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 200))).decode('latin-1')


def _alphabet_text(rng, seed):
    alphabet = sorted(set(seed)) or ['x']
    return ''.join(rng.choice(alphabet) for _ in range(rng.randint(0, 2 * len(seed) + 8)))


def _truncate(rng, seed):
    cut = rng.randint(0, len(seed))
    return seed[:cut] if rng.random() < 0.7 else seed[cut:]


def _flip(rng, seed):
    data = bytearray(seed.encode())
    for _ in range(rng.randint(1, 4)):
        if data:
            data[rng.randrange(len(data))] = rng.getrandbits(8)
    return data.decode('utf-8', errors='replace')


def _insert(rng, seed):
    position = rng.randint(0, len(seed))
    piece = rng.choice([_random_bytes(rng, seed)[:8], rng.choice(_SEPARATORS),
                        rng.choice(_EXTREME_NUMBERS), seed[:rng.randint(0, len(seed))],
                        '\x00', '\r\n', '\u2028', '\ud800'])
    return seed[:position] + piece + seed[position:]


def _delete(rng, seed):
    start = rng.randint(0, len(seed))
    return seed[:start] + seed[start + rng.randint(1, 12):]


def _fields(rng, seed):
    separator = rng.choice([s for s in _SEPARATORS if s in seed] or [' '])
    return separator, seed.split(separator)


def _duplicate_field(rng, seed):
    separator, fields = _fields(rng, seed)
    k = rng.randrange(len(fields))
    fields.insert(k, fields[k])
    return separator.join(fields)


def _swap_or_drop_field(rng, seed):
    separator, fields = _fields(rng, seed)
    if len(fields) > 1 and rng.random() < 0.5:
        i, j = rng.sample(range(len(fields)), 2)
        fields[i], fields[j] = fields[j], fields[i]
    else:
        del fields[rng.randrange(len(fields))]
    return separator.join(fields)


def _extreme_number(rng, seed):
    """Replace one run of digits (a number or an id) by an extreme value."""
    runs, start = [], None
    for k, char in enumerate(seed + ' '):
        if char.isdigit() or char in '.-+eE' and start is not None:
            start = k if start is None else start
        elif start is not None:
            runs.append((start, k))
            start = None
    if not runs:
        return seed + rng.choice(_EXTREME_NUMBERS)
    begin, end = rng.choice(runs)
    return seed[:begin] + rng.choice(_EXTREME_NUMBERS) + seed[end:]


def _splice(rng, seed, others=()):
    other = rng.choice(others) if others else seed
    return seed[:rng.randint(0, len(seed))] + other[rng.randint(0, len(other)):]


def _repeat(rng, seed):
    return seed * rng.randint(2, 200)


#: name -> mutation(rng, seed line) -> line.
LINE_MUTATIONS = {'random bytes': _random_bytes, 'random latin-1': _random_latin1,
                  'format alphabet': _alphabet_text, 'truncation': _truncate,
                  'byte flips': _flip, 'insertion': _insert, 'deletion': _delete,
                  'duplicated field': _duplicate_field, 'swapped/dropped field':
                  _swap_or_drop_field, 'extreme number': _extreme_number, 'splice': _splice,
                  'repeat': _repeat}


def _record_escape(escapes, kind, value, error):
    """Count an escape under its type and place; keep the first input and traceback of each."""
    frame = traceback.extract_tb(error.__traceback__)[-1]
    where = f'{type(error).__name__} at {frame.filename.rsplit("/", 2)[-1]}:{frame.lineno}'
    for escape in escapes:
        if escape['where'] == where:
            escape['count'] += 1
            return
    if len(escapes) < KEEP_ESCAPES:
        escapes.append({'where': where, 'count': 1, 'mutation': kind,
                        'input': repr(value)[:300], 'error': repr(error)[:300],
                        'traceback': ''.join(traceback.format_exception(error))})


def _mutated_line(mutate, rng, seeds):
    """Mutate a random one of the real lines ``seeds`` (a splice also takes the others)."""
    original = rng.choice(seeds)
    return mutate(rng, original, seeds) if mutate is _splice else mutate(rng, original)


def fuzz_protocol(name, inputs, seed=0):
    """
    Feed ``inputs`` generated lines of one protocol (or ``'auto'``) to decoder and assembler.

    Returns
    -------
    dict
        ``protocol``, ``inputs``, ``parsed`` (lines that gave records), ``frames``,
        ``escaped`` (exceptions), ``escapes`` (the first few: type, input, traceback),
        ``by_mutation`` (inputs per mutation), ``seconds``.

    """
    rng = random.Random(f'{seed}:{name}')
    names = list(FORMATS) if name == 'auto' else [name]
    seeds = [line for each in names for line in protocol_seeds(each, rng)]
    decoder = LineDecoder(name)
    assembler, source_tag, source_anchor = _assembler_for(names[0])
    mutations = list(LINE_MUTATIONS.items())
    by_mutation = dict.fromkeys(LINE_MUTATIONS, 0)
    escapes, escaped, parsed, frames = [], 0, 0, 0
    start = time.perf_counter()
    for k in range(inputs):
        kind, mutate = mutations[k % len(mutations)]
        line = None
        try:
            line = _mutated_line(mutate, rng, seeds)
            if name == 'auto' and k % 5 == 0:
                decoder = LineDecoder('auto')            # detect afresh now and then
            records = decoder.decode(line)
            if records:
                parsed += 1
                line_format = decoder.format
                whole = line_format is not None and line_format.whole_tag
                frames += len(assembler.add_line(records, 1.0 + 0.01 * k, source_tag, whole,
                                                 source_anchor))
        except Exception as error:  # noqa: BLE001 - what escapes is the measurement
            escaped += 1
            _record_escape(escapes, kind, line, error)
        by_mutation[kind] += 1
    return {'protocol': name, 'inputs': inputs, 'parsed': parsed, 'frames': frames,
            'escaped': escaped, 'escapes': escapes, 'by_mutation': by_mutation,
            'seconds': time.perf_counter() - start}


# --- configuration values ------------------------------------------------------------------

def shipped_parameters():
    """Return the pump parameters of the packaged ``config/pump.yaml``."""
    with open(default_config_path()) as stream:
        values = yaml.safe_load(stream)['/**']['ros__parameters']
    return {name: value for name, value in values.items() if name in PUMP_PARAMETERS}


def _scalar(rng):
    return rng.choice([None, True, False, 0, -1, 1, -7.5, 3.5, float('nan'), float('inf'),
                       float('-inf'), 10 ** 400, -10 ** 400, 1e308, -1e308, 5e-324, '', ' ',
                       'x', '0', '1782', '-1', 'nan', 'inf', '0x1782', '1e309', '\x00',
                       '\u00e9\u4e2d', 'a' * 10000, b'1782', datetime.date(2026, 1, 1),
                       {}, {'a': 1}, [], [[]]])


def _value_wrong_type(rng, shipped):
    return _scalar(rng)


def _value_list_of_scalars(rng, shipped):
    return [_scalar(rng) for _ in range(rng.randint(0, 12))]


def _value_element_changed(rng, shipped):
    if not isinstance(shipped, list) or not shipped:
        return _scalar(rng)
    value = list(shipped)
    value[rng.randrange(len(value))] = _scalar(rng)
    return value


def _value_length_changed(rng, shipped):
    value = list(shipped) if isinstance(shipped, list) else [shipped]
    if value and rng.random() < 0.5:
        del value[rng.randrange(len(value)):]
    else:
        value += [rng.choice(value) if value else _scalar(rng)
                  for _ in range(rng.randint(1, 6))]
    return value


def _value_duplicates(rng, shipped):
    value = list(shipped) if isinstance(shipped, list) else [shipped]
    return value + value[:rng.randint(1, max(1, len(value)))]


def _value_nested(rng, shipped):
    value = list(shipped) if isinstance(shipped, list) else [shipped]
    for _ in range(rng.randint(1, 3)):
        value = [value] if rng.random() < 0.5 else [value, _scalar(rng)]
    return value


def _value_numbers(rng, shipped):
    count = len(shipped) if isinstance(shipped, list) else 1
    numbers = [rng.choice([float('nan'), float('inf'), -float('inf'), -rng.uniform(0, 1e3),
                           0.0, rng.uniform(-1e9, 1e9), 1e308, 10 ** 400, -0.0])
               for _ in range(count)]
    return numbers if isinstance(shipped, list) else numbers[0]


def _value_huge(rng, shipped):
    count = rng.choice([1000, 10000])
    item = rng.choice([1.0, '1782', 0, 'joint', float('nan')])
    return [item] * count if rng.random() < 0.5 else [f'{item}{k}' for k in range(count)]


def _value_string(rng, shipped):
    text = repr(shipped)
    return rng.choice([text, text[:rng.randint(0, len(text))], str(shipped).upper(),
                       ''.join(chr(rng.randint(0, 0x10FFFF) if rng.random() < 0.3 else
                                   rng.randint(32, 126)) for _ in range(rng.randint(0, 40)))
                       .encode('utf-8', 'surrogatepass').decode('utf-8', 'replace')])


def _value_empty(rng, shipped):
    return rng.choice(['', [], [''], [' '], None, {}, [[]], ['', '']])


def _value_negative(rng, shipped):
    if isinstance(shipped, list):
        return [-abs(v) if isinstance(v, (int, float)) else f'-{v}' for v in shipped]
    return -abs(shipped) if isinstance(shipped, (int, float)) else f'-{shipped}'


#: name -> mutation(rng, shipped value) -> value.
VALUE_MUTATIONS = {'wrong type': _value_wrong_type, 'list of anything': _value_list_of_scalars,
                   'one element changed': _value_element_changed,
                   'length changed': _value_length_changed, 'duplicates': _value_duplicates,
                   'nested lists': _value_nested, 'NaN/inf/huge numbers': _value_numbers,
                   'huge list': _value_huge, 'string': _value_string, 'empty': _value_empty,
                   'negative': _value_negative}

#: Mutations too slow to run at every turn: one input in this many is one of them.
_SLOW = {'huge list': 1000}


def _split_mutations():
    """Return :data:`VALUE_MUTATIONS` as (name, mutation) lists: the fast ones, the slow ones."""
    fast = [(kind, mutate) for kind, mutate in VALUE_MUTATIONS.items() if kind not in _SLOW]
    slow = [(kind, mutate) for kind, mutate in VALUE_MUTATIONS.items() if kind in _SLOW]
    return fast, slow


def _value_mutation(k, fast, slow):
    """Return the ``k``-th input's mutation: the fast ones in turn, a slow one now and then."""
    every = _SLOW['huge list']
    return slow[k // every % len(slow)] if slow and k % every == 0 else fast[k % len(fast)]


def _described(kind, value):
    """Name a mutated value for ``slowest_input``: its mutation, and its length if it has one."""
    return kind + (f', {len(value)} entries' if isinstance(value, (list, str)) else '')


def fuzz_field(field, inputs, seed=0, base=None):
    """
    Validate ``inputs`` pump descriptions with one field mutated; only ConfigError may escape.

    Returns
    -------
    dict
        ``field``, ``inputs``, ``accepted`` (descriptions that validated), ``refused``
        (ConfigError), ``escaped`` (anything else), ``escapes`` (the first few),
        ``seconds``, ``slowest_s`` and ``slowest_input`` (the longest validation).

    """
    rng = random.Random(f'{seed}:{field}')
    base = shipped_parameters() if base is None else base
    shipped = base.get(field, PUMP_PARAMETERS[field][0])
    fast, slow = _split_mutations()
    escapes, escaped, accepted, refused = [], 0, 0, 0
    slowest = (0.0, '')
    start = time.perf_counter()
    for k in range(inputs):
        kind, mutate = _value_mutation(k, fast, slow)
        value = None
        begun = time.perf_counter()
        try:
            value = mutate(rng, shipped)
            begun = time.perf_counter()
            pump_config_from_parameters({**base, field: value})
            accepted += 1
        except ConfigError:
            refused += 1
        except Exception as error:  # noqa: BLE001 - what escapes is the measurement
            escaped += 1
            _record_escape(escapes, kind, value, error)
        took = time.perf_counter() - begun
        if took > slowest[0]:
            slowest = (took, _described(kind, value))
    return {'field': field, 'inputs': inputs, 'accepted': accepted, 'refused': refused,
            'escaped': escaped, 'escapes': escapes, 'seconds': time.perf_counter() - start,
            'slowest_s': slowest[0], 'slowest_input': slowest[1]}


@dataclasses.dataclass
class FuzzReport:
    """
    The report of ``python3 dev.py bench fuzz`` (see :func:`run`).

    Attributes
    ----------
    inputs : int
        Per protocol and per field.
    seed : int
    protocols : list of dict
        :func:`fuzz_protocol` rows.
    fields : list of dict
        :func:`fuzz_field` rows.
    escaped : int
        Exceptions that escaped, in all.

    """

    inputs: int
    seed: int
    protocols: list
    fields: list
    escaped: int
    suite: str = 'fuzz'


def run(inputs=100_000, seed=0, progress=None, protocols=None, fields=None):
    """Fuzz every protocol (and ``auto``) and every configuration field; a :class:`FuzzReport`."""
    protocol_rows, field_rows = [], []
    for name in protocols or [*FORMATS, 'auto']:
        protocol_rows.append(fuzz_protocol(name, inputs, seed))
        if progress:
            progress(f'fuzz {name}: {protocol_rows[-1]["escaped"]} escaped')
    base = shipped_parameters()
    for field in fields or list(PUMP_PARAMETERS):
        field_rows.append(fuzz_field(field, inputs, seed, base))
        if progress:
            progress(f'fuzz {field}: {field_rows[-1]["escaped"]} escaped')
    escaped = sum(row['escaped'] for row in protocol_rows + field_rows)
    return FuzzReport(inputs, seed, protocol_rows, field_rows, escaped)
