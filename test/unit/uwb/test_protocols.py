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

"""UWB line protocols: example lines, corrupted lines, round trips, fuzzing, detection."""
import math

from epp_ros.uwb.formats import detect_format as detect_protocol, FORMATS
from epp_ros.uwb.formats.arduino import format_arduino, parse_arduino
from epp_ros.uwb.formats.base import ParseResult, RangeRecord
from epp_ros.uwb.formats.json_links import format_json, parse_json
from epp_ros.uwb.formats.lec import format_lec, parse_lec
from epp_ros.uwb.formats.trek import format_trek, parse_trek
from hypothesis import given, settings, strategies as st
import pytest

TREK_LINE = 'mc 07 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0'
TREK_RECORDS = (RangeRecord('0', 1.260, '0'), RangeRecord('1', 2.286, '0'),
                RangeRecord('2', 2.174, '0'))
LEC_LINE = ('DIST,4,AN0,022E,7.94,8.03,0.00,3.44,AN1,9280,7.95,0.00,0.00,5.68,'
            'AN2,DC9B,0.00,7.91,0.00,5.25,AN3,15BA,0.00,0.00,0.00,2.10,POS,6.95,5.37,-1.97,52')
LEC_RECORDS = (RangeRecord('022E', 3.44), RangeRecord('9280', 5.68), RangeRecord('DC9B', 5.25),
               RangeRecord('15BA', 2.10))
LEC_CORRUPTED = ('DIST,4,AN0,022E,7.94,8.03,0.00,3.44,AN1,9280,7.95,0.00,0.00,5.68,'
                 'AN2,DC9B,0.00,7.91,0.00,5.25,AN3,15BA,0.00,0,AN3,15BA,0.00,0.00,0.00,0.00')
ARDUINO_LINE = 'from: 1782\t Range: 2.34 m\t RX power: -78.32 dBm'
JSON_LINE = '{"tag":"1","links":[{"A":"1782","R":"2.3"}]}'
EXAMPLES = {'trek': TREK_LINE, 'lec': LEC_LINE, 'arduino': ARDUINO_LINE, 'json': JSON_LINE}
JUNK = bytes(range(256)).decode('utf-8', errors='replace')
# The first four formats, by the names their modules give them.
PARSERS = {'trek': parse_trek, 'lec': parse_lec, 'arduino': parse_arduino, 'json': parse_json}
FORMATTERS = {'trek': format_trek, 'lec': format_lec, 'arduino': format_arduino,
              'json': format_json}
FUZZ = settings(max_examples=250, deadline=None)
ROUND_TRIP = settings(max_examples=200, deadline=None)


def assert_well_formed(result):
    """None, or a ParseResult of valid records with normalised ids."""
    if result is None:
        return
    assert isinstance(result, ParseResult)
    assert isinstance(result.records, tuple) and result.records
    assert type(result.errors) is int and result.errors >= 0
    for record in result.records:
        assert isinstance(record, RangeRecord)
        assert type(record.range_m) is float
        assert math.isfinite(record.range_m) and record.range_m >= 0
        assert record.anchor and record.anchor == record.anchor.strip().upper()
        assert record.tag is None or (record.tag and record.tag == record.tag.strip().upper())
        assert record.kind in ('range', 'raw', 'anchor')
        assert record.rx_power_dbm is None or math.isfinite(record.rx_power_dbm)


# --- TREK1000 ---------------------------------------------------------------------------

def test_trek_example_line():
    assert parse_trek(TREK_LINE) == ParseResult(TREK_RECORDS, 0)
    assert parse_trek(TREK_LINE + '\r\n') == ParseResult(TREK_RECORDS, 0)


def test_trek_tag_is_the_first_number_of_the_token():
    result = parse_trek('mc 0f 00000663 000005a3 00000512 000004cb 095b c1 00024bed t3:1')
    assert [record.tag for record in result.records] == ['3'] * 4
    assert [record.anchor for record in result.records] == ['0', '1', '2', '3']
    assert result.records[3].range_m == 0x4cb / 1000


def test_trek_raw_ranges_are_marked_raw():
    result = parse_trek('mr 01 000004f0 00000000 00000000 00000000 6cc0 0a 40344034 a2:0')
    assert result == ParseResult((RangeRecord('0', 1.264, '2', kind='raw'),), 0)


def test_trek_anchor_anchor_line_maps_fields_to_anchor_pairs():
    result = parse_trek('ma 0e 00000000 00001388 00001b58 00000fa0 0001 05 00001234 a0:0')
    assert result == ParseResult((RangeRecord('1', 5.0, '0', 'anchor'),
                                  RangeRecord('2', 7.0, '0', 'anchor'),
                                  RangeRecord('2', 4.0, '1', 'anchor')), 0)
    # field 0 has no anchor pair
    assert parse_trek('ma 03 00000001 00001388 00000000 00000000 0001 05 0 a0:0') == \
        ParseResult((RangeRecord('1', 5.0, '0', 'anchor'),), 1)


@pytest.mark.parametrize('line, records, errors', [
    ('mc 07 000004ec 000008ee 0000', (RangeRecord('0', 1.26), RangeRecord('1', 2.286)), 2),
    (TREK_LINE.replace('000008ee', '000008eg'), TREK_RECORDS[::2], 1),  # bad hex
    (TREK_LINE.replace('000008ee', 'nan'), TREK_RECORDS[::2], 1),
    (TREK_LINE.replace('000008ee', 'ffffff9c'), TREK_RECORDS[::2], 1),  # negative (-100 mm)
    (TREK_LINE + ' 00c8 extra', TREK_RECORDS, 0),                     # trailing fields
    (TREK_LINE.replace(' a0:0', ''), tuple(RangeRecord(r.anchor, r.range_m)
                                           for r in TREK_RECORDS), 1),
    (JUNK + TREK_LINE, TREK_RECORDS, 1),                              # noise before the line
])
def test_trek_corrupted_lines_keep_the_valid_ranges(line, records, errors):
    assert parse_trek(line) == ParseResult(records, errors)


@pytest.mark.parametrize('line', [
    '', '\r\n', JUNK, 'mc', 'mc zz 000004ec', 'mc 7 000004ec a0:0', 'mx 07 000004ec a0:0',
    'mc 00 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0',  # no valid bit
    'mc 01 nan 0 0 0 0 0 0 a0:0', 'comma 07 000004ec', TREK_LINE[:8]])
def test_trek_lines_without_a_valid_range_give_none(line):
    assert parse_trek(line) is None


# --- DWM1001 lec ------------------------------------------------------------------------

def test_lec_example_line():
    assert parse_lec(LEC_LINE) == ParseResult(LEC_RECORDS, 0)
    assert parse_lec(LEC_LINE + '\r\n') == ParseResult(LEC_RECORDS, 0)
    assert parse_lec(LEC_LINE.split(',POS')[0]) == ParseResult(LEC_RECORDS, 0)


def test_lec_corrupted_firmware_line_salvages_the_three_valid_groups():
    result = parse_lec(LEC_CORRUPTED)
    assert result.records == LEC_RECORDS[:3]
    # the truncated AN3 group, its ambiguous repeat, and 5 groups where 4 were declared
    assert result.errors == 3


@pytest.mark.parametrize('line, records, errors', [
    ('DIST,3,AN0,022E,7.94,8.03,0.00,3.44', LEC_RECORDS[:1], 1),        # count mismatch
    (LEC_LINE.replace('9280', '92G0'), LEC_RECORDS[::2] + LEC_RECORDS[3:], 1),  # bad hex id
    (LEC_LINE.replace('5.68', 'nan'), LEC_RECORDS[::2] + LEC_RECORDS[3:], 1),
    (LEC_LINE.replace('5.68', '-0.12'), LEC_RECORDS[::2] + LEC_RECORDS[3:], 1),
    (LEC_LINE.replace('5.68', '5.68,0.1'), LEC_RECORDS[::2] + LEC_RECORDS[3:], 1),  # extra
    (LEC_LINE.replace('7.95', '1e999'), LEC_RECORDS[::2] + LEC_RECORDS[3:], 1),  # huge x
    (LEC_LINE[:LEC_LINE.index('AN3') + 12], LEC_RECORDS[:3], 1),      # truncated group
    (LEC_LINE.replace(',52', ',5x'), LEC_RECORDS, 1),                  # bad POS
    (LEC_LINE.replace('DIST,4', 'DIST,x'), LEC_RECORDS, 1),            # bad count
    (LEC_LINE.replace('DIST,4,', 'DIST,4,junk,'), LEC_RECORDS, 1),
    (JUNK + LEC_LINE, LEC_RECORDS, 1),
])
def test_lec_corrupted_lines_keep_the_valid_groups(line, records, errors):
    assert parse_lec(line) == ParseResult(records, errors)


@pytest.mark.parametrize('line', [
    '', JUNK, 'DIST', 'DIST,0', 'DIST,1,AN0,022E,7.94', 'POS,1,2,3,50', 'XDIST,1,AN0,1,0,0,0,1',
    'DIST,1,AN0,022E,7.94,8.03,0.00,inf', 'DIST,1,AN0,,7.94,8.03,0.00,1.00'])
def test_lec_lines_without_a_valid_group_give_none(line):
    assert parse_lec(line) is None


# --- arduino-dw1000 ---------------------------------------------------------------------

def test_arduino_example_line():
    expected = ParseResult((RangeRecord('1782', 2.34, rx_power_dbm=-78.32),), 0)
    assert parse_arduino(ARDUINO_LINE) == expected
    assert parse_arduino(ARDUINO_LINE + '\r\n') == expected
    assert parse_arduino('from:1782   Range:2.34m  RX power:-78.32dBm') == expected


@pytest.mark.parametrize('line, record, errors', [
    ('from: 1a2b\t Range: 0.50 m', RangeRecord('1A2B', 0.5), 0),
    ('from: 1782\t Range: 2.34 m (2.30 m)\t RX power: -78.32 dBm',
     RangeRecord('1782', 2.34, rx_power_dbm=-78.32), 0),
    ('from: 1782\t Range: 2.34 m\t RX power: nan dBm', RangeRecord('1782', 2.34), 1),
    ('from: 1782\t Range: 2.34 m\t RX power: -78.3', RangeRecord('1782', 2.34), 1),
    ('Tag:from: 1782\t Range: 2.34 m', RangeRecord('1782', 2.34), 0),
    (JUNK + ARDUINO_LINE, RangeRecord('1782', 2.34, rx_power_dbm=-78.32), 0),
])
def test_arduino_variants(line, record, errors):
    assert parse_arduino(line) == ParseResult((record,), errors)


@pytest.mark.parametrize('line', [
    '', JUNK, 'from: 1782', 'from: 1782\t Range: nan m', 'from: 1782\t Range: ovf m',
    'from: 1782\t Range: inf m', 'from: 1782\t Range: -0.05 m', 'from: \t Range: 2.34 m',
    'Range: 2.34 m\t RX power: -78.32 dBm\t Sampling: 5.00 Hz', 'from: 17\ufffd82 Range: 2 m'])
def test_arduino_lines_without_a_valid_range_give_none(line):
    assert parse_arduino(line) is None


# --- JSON -------------------------------------------------------------------------------

def test_json_example_line():
    expected = ParseResult((RangeRecord('1782', 2.3, '1'),), 0)
    assert parse_json(JSON_LINE) == expected
    assert parse_json(JSON_LINE + '\r\n') == expected
    assert parse_json('{"tag": 1, "links": [{"A": 1782, "R": 2.3}]}') == expected


@pytest.mark.parametrize('line, records, errors', [
    ('{"links":[{"A":"a1","R":"1.5"}]}', (RangeRecord('A1', 1.5),), 0),
    ('{"tag":"1","links":[{"A":"1782","R":"2.3"},{"A":"1783"}]}',
     (RangeRecord('1782', 2.3, '1'),), 1),
    ('{"tag":"1","links":[{"A":"1782","R":"2.3"},{"A":"1783","R":"NaN"},'
     '{"A":"1784","R":NaN},{"A":true,"R":1},{"A":"1785","R":true},{"A":"1786","R":-1},'
     '{"A":"17 86","R":1},{"A":1.5,"R":1},{"A":"1787","R":1e999},7]}',
     (RangeRecord('1782', 2.3, '1'),), 9),
    (JSON_LINE + ' {"tag"', (RangeRecord('1782', 2.3, '1'),), 1),
    (JUNK + JSON_LINE, (RangeRecord('1782', 2.3, '1'),), 1),
])
def test_json_broken_links_are_counted(line, records, errors):
    assert parse_json(line) == ParseResult(records, errors)


@pytest.mark.parametrize('line', [
    '', JUNK, '[]', '"x"', '{}', '{"tag":"1"}', '{"tag":"1","links":{}}', '{"links":[]}',
    '{"tag":[1],"links":[{"A":"1782","R":"2.3"}]}', '{"tag":"","links":[{"A":"1","R":1}]}',
    JSON_LINE[:-3], '{"links":[{"A":"1","R":1}]' + ']' * 10, '[' * 100000 + ']' * 100000,
    '{"links":[{"A":"1","R":' + '9' * 5000 + '}]}', '{"a":' * 100000])
def test_json_lines_without_a_valid_link_give_none(line):
    assert parse_json(line) is None


# --- formatters and round trips ---------------------------------------------------------

def test_the_registry_parses_with_these_parsers():
    assert all(FORMATS[name].parse is PARSERS[name] for name in PARSERS)


def test_formatters_match_the_example_lines():
    assert format_trek('0', {'0': 1.26, '1': 2.286, '2': 2.174}, sequence=0x6cc0a) == \
        'mc 07 000004ec 000008ee 0000087e 00000000 cc0a 0a 00000000 a0:0'
    assert format_lec({'022E': 3.44}, {'022E': (7.94, 8.03, 0.0)}, (6.95, 5.37, -1.97, 52)) \
        == 'DIST,1,AN0,022E,7.94,8.03,0.00,3.44,POS,6.95,5.37,-1.97,52'
    assert format_arduino('1782', 2.34, -78.32) == ARDUINO_LINE
    assert format_json('1', {'1782': 2.3}) == '{"tag":"1","links":[{"A":"1782","R":"2.300"}]}'


@pytest.mark.parametrize('call', [
    lambda: format_trek('0', {'4': 1.0}),
    lambda: format_trek('0', {'0': 1.0}, kind='ma'),
    lambda: format_trek('0', {'0': 1.0}, kind='mx'),
    lambda: format_trek('A', {'0': 1.0}),
    lambda: format_trek('0', {'0': -1.0}),
    lambda: format_trek('0', {'0': 3e6}),
    lambda: format_lec({'XYZ': 1.0}),
    lambda: format_lec({'22e': 1.0, '22E': 2.0}),
    lambda: format_lec({'22E': math.nan}),
    lambda: format_lec({'22E': 1.0}, {'22E': (0.0, math.inf, 0.0)}),
    lambda: format_lec({'22E': 1.0}, position=(1.0, 2.0)),
    lambda: format_arduino('17 82', 1.0),
    lambda: format_arduino('1782', math.inf),
    lambda: format_arduino('1782', 1.0, math.nan),
    lambda: format_json('1', {'': 1.0}),
    lambda: format_json('1', {'1782': -0.5}),
])
def test_formatters_reject_what_their_parser_would_drop(call):
    with pytest.raises(ValueError):
        call()


METRES = st.floats(0.0, 2000.0, allow_nan=False, allow_infinity=False)


def assert_close_records(records, expected, tolerance):
    """Assert records equal to ``expected`` up to the format's precision in the range."""
    assert len(records) == len(expected)
    for record, (anchor, metres, tag, kind) in zip(records, expected):
        assert (record.anchor, record.tag, record.kind) == (anchor, tag, kind)
        assert abs(record.range_m - metres) <= tolerance + 1e-9


@ROUND_TRIP
@given(tag=st.integers(0, 255), ranges=st.dictionaries(st.sampled_from('0123'), METRES,
                                                       min_size=1),
       kind=st.sampled_from(['mc', 'mr']), sequence=st.integers(0, 2 ** 40))
def test_trek_round_trip(tag, ranges, kind, sequence):
    result = parse_trek(format_trek(str(tag), ranges, kind, sequence))
    expected = [(anchor, ranges[anchor], str(tag), 'range' if kind == 'mc' else 'raw')
                for anchor in sorted(ranges)]
    assert result.errors == 0
    assert_close_records(result.records, expected, 0.0005)


@ROUND_TRIP
@given(ranges=st.dictionaries(st.sampled_from('123'), METRES, min_size=1))
def test_trek_anchor_anchor_round_trip(ranges):
    result = parse_trek(format_trek('0', ranges, 'ma'))
    pairs = {'1': ('1', '0'), '2': ('2', '0'), '3': ('2', '1')}
    expected = [(*pairs[field][:1], ranges[field], pairs[field][1], 'anchor')
                for field in sorted(ranges)]
    assert result.errors == 0
    assert_close_records(result.records, expected, 0.0005)


HEX_IDS = st.integers(0, 0xFFFFFFFF).map('{:x}'.format)
COORDINATE = st.floats(-500.0, 500.0, allow_nan=False, allow_infinity=False)


@ROUND_TRIP
@given(ranges=st.dictionaries(HEX_IDS, METRES, min_size=1, max_size=8),
       coordinates=st.lists(st.tuples(COORDINATE, COORDINATE, COORDINATE), min_size=8,
                            max_size=8),
       position=st.none() | st.tuples(COORDINATE, COORDINATE, COORDINATE, st.integers(0, 100)))
def test_lec_round_trip(ranges, coordinates, position):
    anchors_xyz = dict(zip(ranges, coordinates))
    result = parse_lec(format_lec(ranges, anchors_xyz, position))
    expected = [(anchor.upper(), metres, None, 'range') for anchor, metres in ranges.items()]
    assert result.errors == 0
    assert_close_records(result.records, expected, 0.005)


@ROUND_TRIP
@given(anchor=st.from_regex(r'[0-9A-Za-z:._-]{1,12}', fullmatch=True), metres=METRES,
       power=st.none() | st.floats(-130.0, 0.0, allow_nan=False))
def test_arduino_round_trip(anchor, metres, power):
    result = parse_arduino(format_arduino(anchor, metres, power))
    assert result.errors == 0
    assert_close_records(result.records, [(anchor.upper(), metres, None, 'range')], 0.005)
    if power is None:
        assert result.records[0].rx_power_dbm is None
    else:
        assert abs(result.records[0].rx_power_dbm - power) <= 0.005 + 1e-9


JSON_IDS = (st.integers(0, 10 ** 9).map(str)
            | st.text(st.characters(whitelist_categories=('Lu', 'Ll', 'Nd', 'Pd')),
                      min_size=1, max_size=10))


@ROUND_TRIP
@given(tag=st.none() | JSON_IDS, ranges=st.dictionaries(JSON_IDS, METRES, min_size=1))
def test_json_round_trip(tag, ranges):
    result = parse_json(format_json(tag, ranges))
    tag_id = None if tag is None else tag.upper()
    expected = [(anchor.upper(), metres, tag_id, 'range') for anchor, metres in ranges.items()]
    assert result.errors == 0
    assert_close_records(result.records, expected, 0.0005)


# --- fuzzing ----------------------------------------------------------------------------

@FUZZ
@given(name=st.sampled_from(list(PARSERS)), line=st.text())
def test_parsers_survive_any_text(name, line):
    result = PARSERS[name](line)
    assert_well_formed(result)
    assert PARSERS[name](line + '\r\n') == result


NOISE = st.sampled_from([',', ' ', '\t', ':', 'AN3', 'POS', 'DIST,', 'mc ', 'ma ', 'a0:0',
                         '{', '}', '"R":', '"A":', 'nan', 'NaN', 'inf', '-1', '1e999',
                         'ffffffff', '9' * 400, '\ufffd', '\x00', 'Range:', 'm', 'dBm'])


@st.composite
def mutated_lines(draw):
    """Draw a valid line of any format with a few cuts, insertions, replacements and repeats."""
    text = draw(st.sampled_from([*EXAMPLES.values(), LEC_CORRUPTED]))
    for _ in range(draw(st.integers(1, 4))):
        start = draw(st.integers(0, len(text)))
        end = draw(st.integers(start, min(len(text), start + 12)))
        operation = draw(st.sampled_from(['cut', 'insert', 'replace', 'repeat', 'truncate']))
        if operation == 'cut':
            text = text[:start] + text[end:]
        elif operation == 'insert':
            text = text[:start] + draw(NOISE | st.text(max_size=6)) + text[start:]
        elif operation == 'replace':
            text = text[:start] + draw(NOISE | st.text(max_size=6)) + text[end:]
        elif operation == 'repeat':
            text = text[:end] + text[start:end] + text[end:]
        else:
            text = text[:start]
    return text


@FUZZ
@given(name=st.sampled_from(list(PARSERS)), line=mutated_lines())
def test_parsers_survive_mutated_lines(name, line):
    assert_well_formed(PARSERS[name](line))


@pytest.mark.parametrize('value', [None, b'mc 07 000004ec', 42, ['DIST,1'], {'links': []}])
def test_parsers_return_none_for_non_text(value):
    for parser in PARSERS.values():
        assert parser(value) is None


# --- detection --------------------------------------------------------------------------

GARBAGE = ['', JUNK, 'ranging init; 1 device added ! -> short:1782', 'DIST,0', '{"x":1}',
           'mc zz', 'from: 1782 Range: nan m']


@pytest.mark.parametrize('name', list(PARSERS))
def test_detect_protocol_finds_the_format_among_garbage(name):
    valid = [EXAMPLES[name], EXAMPLES[name] + '\r\n']
    assert detect_protocol(GARBAGE[:3] + valid + GARBAGE[3:]) == name
    assert detect_protocol(iter(valid)) == name


def test_detect_protocol_counts_lines_and_breaks_ties_in_parsers_order():
    assert detect_protocol([]) is None
    assert detect_protocol(GARBAGE) is None
    assert detect_protocol([JSON_LINE, JSON_LINE, ARDUINO_LINE, TREK_LINE]) == 'json'
    assert detect_protocol([JSON_LINE, LEC_LINE, ARDUINO_LINE]) == 'lec'
    assert detect_protocol([ARDUINO_LINE, JSON_LINE]) == 'arduino'
