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

"""Every device format of the registry: real firmware lines, corruption, fuzzing, detection."""
import math

from epp_ros.app.config import load_pump_config, PROTOCOLS
from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.formats import Cycle, detect_format, device_number, FORMATS, recognised
from epp_ros.uwb.formats.base import ParseResult, printed_number, RangeRecord
from epp_ros.uwb.formats.haoru import format_haoru
from epp_ros.uwb.formats.mauwb import format_mauwb
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

FUZZ = settings(max_examples=150, deadline=None)
JUNK = bytes(range(256)).decode('utf-8', errors='replace')
HAORU = ('mc ff 00000504 000004e4 00000576 000005d8 00000630 00000519 000004c2 00000602 '
         '0b3e 5f 0002c3a1 t0:0')
LES = '022E[7.94,8.03,0.00]=3.38 0C8A[0.00,8.00,2.25]=6.51 le_us=3082 est[2.57,1.98,1.37,56]'
NRNG = ('{"utime": 88307220,"nrng": {"seq": 224,"mask": 127,"rng": ["8.088","8.039","1.320"],'
        '"uid": ["1946","5199","5235"]}}')
MAUWB = 'AT+RANGE=tid:1,mask:04,seq:63,range:(0,0,30,0,0,0,0,0),rssi:(0,0,-80.50,0,0,0,0,0)'


def records(*triples, kind='range'):
    """Return RangeRecords of (anchor, tag, metres)."""
    return tuple(RangeRecord(anchor, metres, tag, kind) for anchor, tag, metres in triples)


# --- the registry -------------------------------------------------------------------------

def test_every_format_is_one_descriptor_that_everything_reads():
    assert set(FORMATS) <= set(PROTOCOLS) and PROTOCOLS[-1] == 'auto'
    assert list(FORMATS)[:4] == ['trek', 'lec', 'arduino', 'json']
    for name, line_format in FORMATS.items():
        assert line_format.name == name and line_format.firmware
        assert line_format.id_base in (10, 16)
        result = line_format.parse(line_format.example)
        assert result is not None and result.errors == 0, name
        assert line_format.parse(line_format.example + '\r\n') == result


@pytest.mark.parametrize('name', list(FORMATS))
def test_no_other_format_claims_an_example_line(name):
    others = [other for other, f in FORMATS.items()
              if other != name and f.parse(FORMATS[name].example) is not None]
    assert others == []


# --- lines as the firmware prints them ----------------------------------------------------

HAORU_RECORDS = records(*((str(i), '0', v / 1000) for i, v in enumerate(
    [0x504, 0x4e4, 0x576, 0x5d8, 0x630, 0x519, 0x4c2, 0x602])))


@pytest.mark.parametrize('name, line, expected, errors', [
    # HaoruTech 8 anchors: all valid, only anchors 4-7, trailing RX power, corrupted field
    ('haoru', HAORU, HAORU_RECORDS, 0),
    ('haoru', HAORU.replace('mc ff', 'mc f0'), HAORU_RECORDS[4:], 0),
    ('haoru', HAORU + ' 1e98\r\n', HAORU_RECORDS, 0),
    ('haoru', HAORU.replace('00000630', '0000063z'), HAORU_RECORDS[:4] + HAORU_RECORDS[5:], 1),
    ('haoru', HAORU[:HAORU.index('000004c2')],                               # partial:
     tuple(RangeRecord(r.anchor, r.range_m) for r in HAORU_RECORDS[:6]), 3),  # no token
    ('haoru', JUNK + HAORU, HAORU_RECORDS, 1),
    # DWM1001 les: prompt, CRLF, a broken group, a partial line, a repeated anchor
    ('les', LES, records(('022E', None, 3.38), ('0C8A', None, 6.51)), 0),
    ('les', 'dwm> ' + LES + '\r\n', records(('022E', None, 3.38), ('0C8A', None, 6.51)), 0),
    ('les', LES.replace('=6.51', '=nan'), records(('022E', None, 3.38)), 1),
    ('les', LES[:LES.index('0C8A') + 9], records(('022E', None, 3.38)), 1),
    ('les', LES.replace('0C8A[', '022E['), (), None),
    ('les', JUNK + LES, records(('022E', None, 3.38), ('0C8A', None, 6.51)), 1),
    ('les', LES.replace('est[2.57,1.98,1.37,56]', 'est[2.57,1.9'), records(
        ('022E', None, 3.38), ('0C8A', None, 6.51)), 1),
    # mynewt nrng: the app's form, the library's form, a broken pair, unequal lists
    ('nrng', NRNG, records(('1946', None, 8.088), ('5199', None, 8.039), ('5235', None, 1.32)),
     0),
    ('nrng', '{"utime":1,"seq":2,"uid":4660,"ouid":[4661,4662],"rng":[3.5,2.25]}',
     records(('4661', '4660', 3.5), ('4662', '4660', 2.25)), 0),
    ('nrng', NRNG.replace('"8.039"', '"-1"'), records(('1946', None, 8.088),
                                                      ('5235', None, 1.32)), 1),
    ('nrng', NRNG.replace(',"5235"', ''), records(('1946', None, 8.088),
                                                  ('5199', None, 8.039)), 1),
    # Makerfabs MaUWB AT: centimetres, ancid, missing mask, broken slot, junk
    ('mauwb', MAUWB + '\r\n', records(('2', '1', 0.30)), 0),
    ('mauwb', 'AT+RANGE=tid:0,mask:03,seq:182,range:(232,401,0,0),rssi:(-79.80,-81.10,0,0),'
              'ancid:(0,3,-1,-1)', records(('0', '0', 2.32), ('3', '0', 4.01)), 0),
    ('mauwb', 'AT+RANGE=tid:4,seq:218,range:(100,110,0,0,0,0,0,0)',
     records(('0', '4', 1.0), ('1', '4', 1.1)), 0),
    ('mauwb', MAUWB.replace('mask:04', 'mask:06').replace('(0,0,30', '(0,x,30'),
     records(('2', '1', 0.30)), 1),
    ('mauwb', 'OK\x00' + MAUWB, records(('2', '1', 0.30)), 1),
    ('mauwb_json', '{"id":1,"range":[0,0,30,0,0,0,0,0]}', records(('2', '1', 0.30)), 0),
    ('mauwb_json', '{"id":"7","range":[120,0,"x",0,0,0,0,0]}\r\n', records(('0', '7', 1.2)), 1),
    # jremington: unpadded hex address, CRLF
    ('jremington', 'B82,2.34\r\n', records(('B82', None, 2.34)), 0),
    ('jremington', '81,0.50', records(('81', None, 0.5)), 0),
    # DW1000-ng and DW3000 examples: no device named
    ('bare', 'Range: 1.23 m\t RX power: -78.32 dBm\t Sampling: 5.00 Hz',
     (RangeRecord(None, 1.23, rx_power_dbm=-78.32),), 0),
    ('bare', 'DIST: 1.23 m\r\n', (RangeRecord(None, 1.23),), 0),
    ('bare', 'Range: 1.23 m\t RX power: ovf dBm', (RangeRecord(None, 1.23),), 1),
    # DW1000-ng RTLS anchors: the tag's bytes run together, the anchor's EUI bytes with a colon
    ('ng_rtls', 'Range: 9.04 m\t RX power: -82.30 dBm distance between anchor/tag:40 from '
                'Anchor 00:01', (RangeRecord('00:01', 9.04, '40', rx_power_dbm=-82.3),), 0),
    ('ng_rtls', 'Range: 1.23 m      RX power: -45.67 dBm distance between anchor/tag:01:01 '
                'from Anchor 00:03\r\n', (RangeRecord('00:03', 1.23, '01:01',
                                                      rx_power_dbm=-45.67),), 0),
    ('ng_rtls', 'Range: 0.00 m\t RX power: inf dBm distance between anchor/tag:11 from Anchor '
                '00:02', (RangeRecord('00:02', 0.0, '11'),), 1),
    # thotro and Makerfabs sketches print unpadded addresses too
    ('arduino', 'from: B82\t Range: 2.34 m\t RX power: -78.32 dBm',
     (RangeRecord('B82', 2.34, rx_power_dbm=-78.32),), 0),
    ('json', '{"links":[{"A":"B82","R":"2.3"},{"A":"81","R":"1.0"}]}',
     records(('B82', None, 2.3), ('81', None, 1.0)), 0),
])
def test_firmware_lines(name, line, expected, errors):
    result = FORMATS[name].parse(line)
    if errors is None:
        assert result is None
    else:
        assert result == ParseResult(expected, errors)


@pytest.mark.parametrize('name, line', [
    ('haoru', 'mc 07 000004ec 000008ee 0000087e 00000000 6cc0 0a 00a0642b a0:0'),   # 4 anchors
    ('trek', HAORU),
    ('haoru', 'mc 00 ' + ' '.join(['00000001'] * 8) + ' 0001 01 00000000 t0:0'),
    ('les', 'le_us=3082 est[2.57,1.98,1.37,56]'),
    ('nrng', '{"utime": 88255157,"wcs": [23983557962832,893813779536],"skew": 1}'),
    ('mauwb', 'AT+RANGE=tid:1,mask:00,seq:1,range:(0,0,0,0,0,0,0,0)'),
    ('mauwb', 'AT+SETRPT=1'),
    ('mauwb_json', '{"links":[{"A":"1","R":"1"}],"range":[1]}'),
    ('mauwb_json', '{"id":1,"range":[0,0,0,0,0,0,0,0]}'),
    ('jremington', '1782,2.34,5'),
    ('jremington', 'POS,1.0'),
    ('bare', 'from: 1782\t Range: 2.34 m'),
    ('bare', FORMATS['ng_rtls'].example),
    ('ng_rtls', 'Range: 1.23 m\t RX power: -78.32 dBm\t Sampling: 5.00 Hz'),
    ('ng_rtls', 'Range: 1.23 m distance between anchor/tag:40 from Anchor 00:01:'),
    ('bare', 'Range: nan m'),
])
def test_lines_of_other_formats_or_without_a_range_give_none(name, line):
    assert FORMATS[name].parse(line) is None


@pytest.mark.parametrize('line, label', [
    ('POS,2.57,1.98,1.37,56', 'position'),                       # lep
    ('dwm> POS,0,D1AA,2.57,1.98,1.37,56,x0A\r\n', 'position'),  # listener
    ('le_us=3082 est[2.57,1.98,1.37,56]', 'position'),           # les without anchors
    ('GET / HTTP/1.1', 'preamble'),                              # a WiFi tag's request
    ('Host: 192.168.4.1', 'preamble'),
    ('Connection: close', 'preamble'),
    ('from: 1782 Range: nan m', None),
    ('POS,x', None),
    (JUNK, None),
])
def test_lines_without_ranges_are_recognised_not_garbage(line, label):
    assert recognised(line) == label


def test_the_decoder_counts_positions_and_preambles_apart_from_garbage():
    decoder = LineDecoder('lec')
    for line in ['POS,2.57,1.98,1.37,56', 'garbage', FORMATS['lec'].example]:
        decoder.decode(line)
    assert (decoder.counts['position'], decoder.counts['unparsed'],
            decoder.counts['parsed']) == (1, 1, 1)
    decoder = LineDecoder('auto')
    for line in ['GET / HTTP/1.1', 'Host: 10.0.0.1', 'Connection: close']:
        assert decoder.decode(line) == ()
    assert decoder.counts['preamble'] == 3 and decoder.counts['unparsed'] == 0


# --- ids are numbers --------------------------------------------------------------------

@pytest.mark.parametrize('a, b', [('0B82', 'B82'), ('0x0b82', 'b82'), ('0081', '81'),
                                  (' 1782 ', '0x1782'), (17, '17'), ('0', '0000')])
def test_device_ids_compare_as_hexadecimal_numbers(a, b):
    assert device_number(a) == device_number(b) is not None


@pytest.mark.parametrize('value', ['', 'xyz', '0x', '-1', -1, True, None, 1.5, '1' * 17])
def test_what_is_not_an_id_has_no_number(value):
    assert device_number(value) is None


def test_decimal_printing_firmware_gets_its_digits():
    assert printed_number('03') == '3' and printed_number('0x12') == '12'
    with pytest.raises(ValueError):
        printed_number('A')
    with pytest.raises(ValueError):
        printed_number('9', maximum=7)


# --- round trips and detection ------------------------------------------------------------

METRES = st.floats(0.1, 400.0, allow_nan=False, allow_infinity=False)
PRECISION = {'trek': 5e-4, 'haoru': 5e-4, 'json': 5e-4, 'nrng': 5e-4, 'mauwb': 5e-3,
             'mauwb_json': 5e-3}


@settings(max_examples=100, deadline=None)
@given(name=st.sampled_from(list(FORMATS)), tag=st.integers(0, 7),
       ranges=st.dictionaries(st.integers(0, 7).map(str), METRES, min_size=1),
       sequence=st.integers(0, 2 ** 20))
def test_every_emitter_is_read_back_by_its_parser(name, tag, ranges, sequence):
    line_format = FORMATS[name]
    if not line_format.names_anchor:
        ranges = dict(list(ranges.items())[:1])
    slots = line_format.anchor_slots or 8
    ranges = {a: v for a, v in ranges.items() if int(a) < slots} or {'0': 1.0}
    lines = line_format.emit(str(tag), ranges, Cycle(sequence, {}, -80.0))
    got = {}
    for line in lines:
        result = line_format.parse(line)
        assert result is not None and result.errors == 0
        for record in result.records:
            if record.kind == 'range':
                assert record.tag in (None, str(tag))
                got[record.anchor] = record.range_m
    if not line_format.names_anchor:
        assert list(got) == [None]
        got = {next(iter(ranges)): got[None]}
    assert {device_number(a) for a in got} == {device_number(a) for a in ranges}
    tolerance = PRECISION.get(name, 5e-3) + 1e-9
    for anchor, value in got.items():
        expected = next(v for a, v in ranges.items() if device_number(a) == device_number(anchor))
        assert abs(value - expected) <= tolerance


def positional_config():
    import dataclasses
    config = load_pump_config()
    return dataclasses.replace(config, anchor_ids=tuple(str(i) for i in range(6)))


@pytest.mark.parametrize('name', list(FORMATS))
def test_auto_detection_settles_on_every_format_within_a_few_lines(name):
    from epp_ros.uwb.emulation import cycle_lines
    config = positional_config() if FORMATS[name].anchor_slots else load_pump_config()
    if name == 'trek':
        import dataclasses
        config = dataclasses.replace(config, anchor_ids=('0', '1', '2', '3'))
        ranges = np.full((5, 4), 4.0)
    else:
        ranges = np.full((5, len(config.anchor_ids)), 4.0)
    lines = [line for _, line in cycle_lines(config, ranges, name, sequence=3)]
    decoder = LineDecoder('auto')
    decoder.decode('\ufffd\ufffd noise after a reconnect')
    for line in lines[:6]:
        decoder.decode(line)
    assert decoder.protocol == name
    assert detect_format(lines[:3]) == name


# --- fuzzing ------------------------------------------------------------------------------

def assert_well_formed(name, result):
    """None, or valid records; ids normalised; anchors absent only where the format says."""
    if result is None:
        return
    assert isinstance(result, ParseResult) and result.records
    assert type(result.errors) is int and result.errors >= 0
    for record in result.records:
        assert type(record.range_m) is float
        assert math.isfinite(record.range_m) and record.range_m >= 0
        if FORMATS[name].names_anchor:
            assert record.anchor and record.anchor == record.anchor.strip().upper()
        else:
            assert record.anchor is None
        assert record.tag is None or (record.tag and record.tag == record.tag.strip().upper())
        assert record.kind in ('range', 'raw', 'anchor')
        assert record.rx_power_dbm is None or math.isfinite(record.rx_power_dbm)


@FUZZ
@given(name=st.sampled_from(list(FORMATS)), line=st.text())
def test_parsers_survive_any_text(name, line):
    result = FORMATS[name].parse(line)
    assert_well_formed(name, result)
    assert FORMATS[name].parse(line + '\r\n') == result
    FORMATS[name].recognise(line)


NOISE = st.sampled_from([',', ' ', '\t', ':', '[', ']', '=', '(', ')', '{', '}', '"', 'nan',
                         '-1', '1e999', 'ffffffff', '9' * 400, '\ufffd', '\x00', 'mask:',
                         'tid:', 'range:(', 'le_us=', 'est[', 'DIST:', 'Range:', 'm', 't0:0'])


@st.composite
def mutated_lines(draw):
    """Draw a valid line of any format with a few cuts, insertions, replacements and repeats."""
    text = draw(st.sampled_from([f.example for f in FORMATS.values()] + [HAORU, LES, NRNG]))
    for _ in range(draw(st.integers(1, 4))):
        start = draw(st.integers(0, len(text)))
        end = draw(st.integers(start, min(len(text), start + 12)))
        insert = draw(NOISE | st.text(max_size=6))
        text = draw(st.sampled_from([text[:start] + text[end:],
                                     text[:start] + insert + text[start:],
                                     text[:start] + insert + text[end:],
                                     text[:end] + text[start:end] + text[end:], text[:start]]))
    return text


@FUZZ
@given(name=st.sampled_from(list(FORMATS)), line=mutated_lines())
def test_parsers_survive_mutated_lines(name, line):
    assert_well_formed(name, FORMATS[name].parse(line))


@pytest.mark.parametrize('value', [None, b'mc ff', 42, ['POS,1'], {'range': []}])
def test_parsers_return_none_for_non_text(value):
    for line_format in FORMATS.values():
        assert line_format.parse(value) is None
        assert line_format.recognise(value) is None


@pytest.mark.parametrize('call', [
    lambda: format_haoru('1', {'8': 1.0}),
    lambda: format_haoru('A', {'0': 1.0}),
    lambda: format_mauwb('1', {'0': -1.0}),
    lambda: FORMATS['jremington'].emit('1', {'12345': 1.0}, Cycle()),
    lambda: FORMATS['les'].emit('1', {'xyz': 1.0}, Cycle()),
    lambda: FORMATS['bare'].emit('1', {None: math.inf}, Cycle()),
])
def test_emitters_refuse_what_the_firmware_cannot_print(call):
    with pytest.raises(ValueError):
        call()


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from([n for n, f in FORMATS.items() if f.emit_anchors]),
       ranges=st.dictionaries(st.tuples(st.integers(0, 3), st.integers(0, 3)).filter(
           lambda pair: pair[0] != pair[1]).map(lambda pair: tuple(map(str, pair))), METRES),
       sequence=st.integers(0, 2 ** 20))
def test_anchor_range_emitters_are_read_back_by_their_parser(name, ranges, sequence):
    line_format = FORMATS[name]
    got = {}
    for line in line_format.emit_anchors(ranges, Cycle(sequence, {}, -80.0)):
        result = line_format.parse(line)
        assert result is not None and result.errors == 0
        assert {record.kind for record in result.records} == {'anchor'}
        got.update({(record.tag, record.anchor): record.range_m for record in result.records})
    # Every pair read back was given; the TREK1000 carries A0-A1, A0-A2 and A1-A2 only.
    assert set(got) <= set(ranges)
    if name == 'trek':
        assert set(got) == set(ranges) & {('0', '1'), ('0', '2'), ('1', '2')}
    for pair, value in got.items():
        assert abs(value - ranges[pair]) <= 5e-4 + 1e-9


def test_only_the_trek1000_prints_anchor_ranges():
    assert [name for name, f in FORMATS.items() if f.emit_anchors] == ['trek']
    line = FORMATS['trek'].emit_anchors({('0', '1'): 5.285, ('0', '2'): 5.285,
                                         ('1', '2'): 6.8, ('2', '3'): 9.0}, Cycle(3))
    assert line == ['ma 0e 00000000 000014a5 000014a5 00001a90 0003 03 00000000 a0:0']
    assert FORMATS['trek'].emit_anchors({('2', '3'): 9.0}, Cycle()) == []


def test_positional_formats_refuse_anchors_beyond_their_fields():
    from epp_ros.uwb.formats import anchor_slot_problem
    six = ['0', '1', '2', '3', '4', '5']
    assert 'at most 4 anchors' in anchor_slot_problem(six, ['trek'])
    assert "['4', '5']" in anchor_slot_problem(six, ['trek'])
    assert anchor_slot_problem(six[:4], ['trek']) is None
    assert anchor_slot_problem(six, ['trek', 'haoru']) is None      # eight fields carry them
    assert anchor_slot_problem(six, ['json']) is None               # names its anchors
    assert anchor_slot_problem(six, ['auto']) is None               # not known until read


def test_a_line_naming_both_devices_keeps_them_under_auto():
    """The real DW1000-ng RTLS anchor line: auto-detection must not read it as bare."""
    line = ('Range: 9.04 m\t RX power: -82.30 dBm distance between anchor/tag:40 from '
            'Anchor 00:01')
    decoder = LineDecoder('auto')
    records = [record for _ in range(4) for record in decoder.decode(line)]
    assert decoder.protocol == 'ng_rtls'
    assert {(r.tag, r.anchor, r.range_m) for r in records} == {('40', '00:01', 9.04)}
    assert device_number('00:01') == device_number('0001') == 1
    assert device_number('0B:82') == 0xB82 and device_number('01:01') == 0x101


def test_each_client_of_a_port_detects_its_own_protocol():
    """A stray client's five arduino lines must not lock the port against a JSON tag."""
    from epp_ros.uwb.decoder import PeerDecoders
    decoders = PeerDecoders('auto')
    stray, tag = 1, 2
    for _ in range(5):
        assert decoders.decoder(stray).decode(FORMATS['arduino'].example)
    json_line = '{"tag":"1","links":[{"A":"1782","R":"2.3"}]}'
    for _ in range(4):
        [record] = decoders.decoder(tag).decode(json_line)
        assert (record.tag, record.anchor, record.range_m) == ('1', '1782', 2.3)
    assert decoders.protocol == 'arduino, json'
    decoders.forget(stray)
    assert decoders.protocol == 'json'
    assert decoders.counts['parsed'] == 9 and decoders.counts['lines'] == 9
    with pytest.raises(ValueError):
        PeerDecoders('morse')
