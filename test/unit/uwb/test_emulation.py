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

"""Emulated device lines decode back to the ranges they were made from."""
import os
from pathlib import Path
import subprocess
import sys

from epp_ros.app.config import load_pump_config, pump_config_from_parameters
from epp_ros.core.simulation.simulate import random_posture, RangeNoise
from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.emulation import channel_count, corrupt, cycle_lines, PtyOutput, TcpOutput
from epp_ros.uwb.frames import FrameAssembler
import numpy as np
import pytest

CONFIG = load_pump_config()
PRECISION = {'json': 1e-3, 'lec': 5e-3, 'arduino': 5e-3, 'trek': 1e-3}


def trek_config():
    import dataclasses
    return dataclasses.replace(CONFIG, anchor_ids=('0', '1', '2', '3'),
                               anchor_names=CONFIG.anchor_names[:4],
                               anchor_positions=CONFIG.anchor_positions[:4],
                               body_anchors=CONFIG.anchor_names[:1])


@pytest.mark.parametrize('protocol', ['json', 'lec', 'arduino', 'trek'])
def test_cycle_lines_decode_to_the_same_frame(protocol):
    config = trek_config() if protocol == 'trek' else CONFIG
    model = config.model()
    rng = np.random.default_rng(0)
    joints = random_posture(model, rng)[2]
    ranges, _ = RangeNoise(dropout=0.2).apply(model.ranges(joints), rng)
    lines = cycle_lines(config, ranges, protocol, sequence=7)
    assert {channel for channel, _ in lines} <= set(range(channel_count(protocol, 5)))
    decoders = [LineDecoder(protocol) for _ in range(channel_count(protocol, 5))]
    assembler = FrameAssembler(config)
    frames = []
    for channel, line in lines:
        tag = None if channel_count(protocol, 5) == 1 else config.tag_ids[channel]
        for record in decoders[channel].decode(line):
            frames += assembler.add(record, 1.0, tag)
    frames += assembler.poll(2.0)
    assert len(frames) == 1
    np.testing.assert_array_equal(np.isnan(frames[0].ranges), np.isnan(ranges))
    np.testing.assert_allclose(frames[0].ranges, ranges, atol=PRECISION[protocol])
    raw = np.isfinite(ranges).sum() if protocol == 'trek' else 0
    assert assembler.dropped == ({'raw_range': raw} if raw else {})


def test_auto_detection_settles_and_keeps_early_records():
    lines = [line for _, line in cycle_lines(CONFIG, np.full((5, 6), 4.0), 'json')]
    decoder = LineDecoder('auto')
    assert decoder.decode('\ufffd\ufffd garbage') == ()
    records = [decoder.decode(line) for line in lines[:3]]
    assert all(len(r) == 6 for r in records) and decoder.protocol == 'json'
    assert decoder.counts['unparsed'] == 1 and decoder.counts['records'] == 18
    with pytest.raises(ValueError):
        LineDecoder('morse')


def test_corrupted_lines_never_raise_in_the_decoder():
    rng = np.random.default_rng(1)
    decoder = LineDecoder('auto')
    for protocol in ('json', 'lec', 'arduino'):
        for _, line in cycle_lines(CONFIG, np.full((5, 6), 4.0), protocol):
            for _ in range(20):
                damaged = corrupt(line, rng).decode('utf-8', errors='replace')
                for record in decoder.decode(damaged):
                    assert np.isfinite(record.range_m) and record.range_m >= 0


def test_pty_output_is_readable_through_its_link(tmp_path):
    link = tmp_path / 'ttyUWB'
    output = PtyOutput(link=str(link))
    try:
        assert output.path == str(link) and os.path.realpath(link) == output.device
        reader = os.open(link, os.O_RDONLY | os.O_NONBLOCK)
        output.write(b'hello\r\n')
        assert os.read(reader, 100) == b'hello\r\n'
        os.close(reader)
    finally:
        output.close()
    assert not os.path.lexists(link)


def test_pty_output_drops_instead_of_blocking_when_nobody_reads():
    output = PtyOutput()
    try:
        for _ in range(2000):
            output.write(b'x' * 100 + b'\n')
        assert output.counts['dropped'] + output.counts['truncated'] > 0
    finally:
        output.close()


def test_tcp_output_serves_clients_after_a_grace_period():
    import socket
    import time
    output = TcpOutput('127.0.0.1', 0, grace=0.1)
    try:
        client = socket.create_connection((output.host, output.port), timeout=2)
        time.sleep(0.05)
        output.write(b'early\n')                # inside the grace period: not sent
        time.sleep(0.15)
        output.write(b'late\n')
        assert client.recv(100) == b'late\n'
        client.close()
    finally:
        output.close()


def test_unknown_protocol_raises():
    with pytest.raises(ValueError):
        cycle_lines(CONFIG, np.full((5, 6), 4.0), 'morse')


def test_config_validation_is_shared_with_the_emulator():
    values = {'tag_names': ['a'], 'tag_ids': ['1'], 'anchor_names': ['x', 'y', 'z'],
              'anchor_ids': ['1', '2', '3'],
              'anchor_positions': [0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 1.0, 2.0, 3.0],
              'arm_lengths': [1.0], 'base': [0.0, 0.0, 0.0], 'source_ports': ['p'],
              'source_protocols': ['json'], 'source_tags': ['']}
    config = pump_config_from_parameters(values)
    assert len(cycle_lines(config, np.array([[1.0, 2.0, np.nan]]), 'arduino')) == 2


def config_for(protocol):
    """Return the packaged pump, with anchors 0-5 (or 0-3) for formats whose anchors are slots."""
    import dataclasses

    from epp_ros.uwb.formats import FORMATS
    slots = FORMATS[protocol].anchor_slots
    if slots is None:
        return CONFIG
    count = min(slots, len(CONFIG.anchor_ids))
    return dataclasses.replace(CONFIG, anchor_ids=tuple(str(i) for i in range(count)),
                               anchor_names=CONFIG.anchor_names[:count],
                               anchor_positions=CONFIG.anchor_positions[:count],
                               body_anchors=CONFIG.anchor_names[:1])


def every_format():
    from epp_ros.uwb.formats import FORMATS
    return list(FORMATS)


@pytest.mark.parametrize('protocol', every_format())
def test_the_emulator_speaks_every_format_and_the_driver_reads_it_back(protocol):
    from epp_ros.uwb.emulation import channel_devices
    config = config_for(protocol)
    model = config.model()
    rng = np.random.default_rng(3)
    ranges, _ = RangeNoise(dropout=0.2).apply(model.ranges(random_posture(model, rng)[2]), rng)
    devices = channel_devices(protocol, config)
    decoders = [LineDecoder('auto') for _ in devices]
    assembler = FrameAssembler(config)
    for channel, line in cycle_lines(config, ranges, protocol, sequence=5):
        tag, anchor = devices[channel]
        assembler.add_line(decoders[channel].decode(line), 1.0, tag, False, anchor)
    (frame,) = assembler.poll(2.0)
    np.testing.assert_array_equal(np.isnan(frame.ranges), np.isnan(ranges))
    np.testing.assert_allclose(frame.ranges, ranges, atol=0.005 + 1e-9)
    assert set(assembler.dropped) <= {'raw_range'}


def console_script(name):
    return str(Path(sys.executable).parent / name)


def test_emulator_draws_from_the_field_simulator_with_field_or_joystick():
    from epp_ros.core.simulation.simulate import FieldSimulator, JoystickMotion
    from epp_ros.nodes import emulator
    model = CONFIG.model()
    args = emulator.parse_args(['--pty', '--field', 'tdma,dropouts', '--motion', 'joystick'])
    assert args.field == 'tdma,dropouts' and args.motion == 'joystick'
    measure = emulator.range_source(args, model, np.random.default_rng(0))
    motion = emulator.ForthAndBack(
        JoystickMotion(model, emulator.PLAYBACK_S, np.random.default_rng(0)),
        emulator.PLAYBACK_S)
    simulator = FieldSimulator(model, emulator.effects_of(args), np.random.default_rng(0),
                               frame_period=0.1)
    for cycle in range(20):
        ranges, joints = measure(cycle)
        frame = simulator.frame(motion, cycle / 10.0)
        np.testing.assert_array_equal(ranges, frame.ranges)
        np.testing.assert_allclose(joints, frame.joints, rtol=1e-12)
    # Played forth and back: the boom never jumps, the noise keeps going.
    folded = emulator.ForthAndBack(motion.motion, 10.0)
    np.testing.assert_allclose(folded.joints([3.0, 17.0, 23.0, -3.0]),
                               motion.joints([3.0, 3.0, 3.0, 3.0]), rtol=1e-12)
    # Joystick without --field: the usual noise options, through the simulator.
    args = emulator.parse_args(['--pty', '--motion', 'joystick', '--drop', '0.5'])
    effects = emulator.effects_of(args)
    assert (effects.sigma, effects.link_dropout, effects.nlos_duration) == (0.05, 0.5, 0.0)


def test_emulator_without_field_draws_as_before():
    from epp_ros.core.simulation.simulate import working_cycle
    from epp_ros.nodes import emulator
    model = CONFIG.model()
    args = emulator.parse_args(['--pty', '--seed', '3', '--sigma', '0.2', '--nlos', '0.1'])
    rng = np.random.default_rng(3)
    measure = emulator.range_source(args, model, np.random.default_rng(3))
    trajectory = working_cycle(model, 600.0, 10.0, rng=np.random.default_rng(3))
    noise = RangeNoise(sigma=0.2, nlos_fraction=0.1, nlos_gamma=2.0)
    for cycle in range(5):
        ranges, joints = measure(cycle)
        np.testing.assert_array_equal(joints, trajectory.joints[cycle])
        np.testing.assert_array_equal(ranges, noise.apply(model.ranges(joints), rng)[0])
    assert emulator.parse_args(['--pty']).sigma == 0.05


@pytest.mark.parametrize('argv, says', [
    (['uwb_emulator', '--pty', '--field', 'fog'], "unknown field effect 'fog'"),
    (['uwb_emulator', '--pty', '--field', 'tdma', '--sigma', '0.1'], '--field'),
    (['uwb_emulator', '--pty', '--motion', 'dance'], '--motion'),
    (['epp_bag', 'synth', 'OUT', '--field', 'tdma,fog'], "unknown field effect 'fog'"),
    (['epp_bag', 'synth', 'OUT', '--field', 'tdma', '--nlos', '0.1'], '--field'),
])
def test_bad_field_options_give_one_line_and_status_2(argv, says, tmp_path):
    args = [console_script(argv[0])] + [str(tmp_path / a) if a == 'OUT' else a
                                        for a in argv[1:]]
    result = subprocess.run(args, capture_output=True, text=True, timeout=60)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert 'error' in lines[0] and says in lines[0]
    assert not (tmp_path / 'OUT').exists()


def test_synth_writes_a_field_bag_with_its_truth(tmp_path):
    from epp_ros.app import bags, contract
    from epp_ros.core.simulation.simulate import WorkingMotion
    bag = tmp_path / 'field'
    result = subprocess.run([console_script('epp_bag'), 'synth', str(bag), '--field',
                             'nlos_persistent,tdma', '--duration', '2', '--seed', '4',
                             '--start', '1000'], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    messages, damage = bags.read_all(bag)
    assert damage.intact
    by_topic = {}
    for topic, msgtype, t_ns, raw, _ in messages:
        by_topic.setdefault(topic, []).append(
            (t_ns, bags.TYPESTORE.deserialize_cdr(raw, msgtype)))
    assert {topic: len(found) for topic, found in by_topic.items()} == \
        {bags.RANGES: 20, bags.TRUTH: 20}
    model = CONFIG.model()
    motion = WorkingMotion(model, np.random.default_rng(4))       # drawn first, as synth does
    for index, (t_ns, message) in enumerate(by_topic[bags.TRUTH]):
        assert t_ns == 1000 * 10 ** 9 + index * 10 ** 8
        np.testing.assert_allclose(contract.joints_of(message), motion.joints(index / 10.0),
                                   atol=1e-9)
    assert [contract.frame_number(m.name, m.position) for _, m in by_topic[bags.RANGES]] == \
        list(range(1, 21))                          # numbered as the driver numbers them
    ranges = np.array([message.position[:-1] for _, message in by_topic[bags.RANGES]])
    assert ranges.shape == (20, 30) and np.isfinite(ranges).any()


def test_emulator_runs_with_field_effects_and_joystick():
    result = subprocess.run([console_script('uwb_emulator'), '--pty', '--field',
                             'nlos_persistent,tdma,dropouts', '--motion', 'joystick',
                             '--duration', '1'], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('PTY ')


def test_anchor_rounds_come_in_a_burst_at_start_up_then_once_a_second():
    from epp_ros.uwb.emulation import anchor_rounds, SURVEY_BURST
    assert [anchor_rounds(cycle, 10.0) for cycle in range(31)] == \
        [SURVEY_BURST] + ([0] * 9 + [1]) * 3
    assert [anchor_rounds(cycle, 1.0) for cycle in range(3)] == [SURVEY_BURST, 1, 1]
    assert [anchor_rounds(cycle, 0.2) for cycle in range(3)] == [SURVEY_BURST, 1, 1]


def test_anchor_lines_decode_to_the_pairs_the_format_carries():
    from epp_ros.uwb.emulation import anchor_lines, reports_anchor_ranges
    config = trek_config()
    ranges = np.arange(16, dtype=float).reshape(4, 4) + 3.0
    np.fill_diagonal(ranges, np.nan)
    ranges[1, 2] = np.nan                                   # not measured this round
    lines = anchor_lines(config, ranges, 'trek', sequence=4)
    assert [channel for channel, _ in lines] == [0] and lines[0][1].startswith('ma ')
    assembler = FrameAssembler(config)
    assembler.add_line(LineDecoder('trek').decode(lines[0][1]), 2.0, None, True)
    anchor_round = assembler.take_anchor_ranges()
    assert (anchor_round.rows, anchor_round.columns) == ([0, 0], [1, 2])
    np.testing.assert_allclose(anchor_round.ranges, [ranges[0, 1], ranges[0, 2]], atol=5e-4)
    assert reports_anchor_ranges('trek') and not reports_anchor_ranges('haoru')
    for protocol in ('json', 'haoru', 'les'):
        assert anchor_lines(config_for(protocol), np.ones((6, 6)), protocol) == []


def test_emulator_anchor_ranges_come_from_the_field_simulator():
    from epp_ros.core.simulation.simulate import FieldSimulator
    from epp_ros.nodes import emulator
    model = trek_config().model()
    args = emulator.parse_args(['--pty', '--field', 'offsets,anchors_moved', '--seed', '5'])
    measure = emulator.range_source(args, model, np.random.default_rng(5))
    simulator = FieldSimulator(model, emulator.effects_of(args), np.random.default_rng(5))
    for _ in range(3):
        np.testing.assert_array_equal(measure.anchor_ranges(), simulator.anchor_ranges())
    # Without --field: the configured anchors, with the noise options' sigma.
    args = emulator.parse_args(['--pty', '--sigma', '0'])
    measure = emulator.range_source(args, model, np.random.default_rng(0))
    distances = np.linalg.norm(model.anchors[:, None] - model.anchors[None], axis=-1)
    np.fill_diagonal(distances, np.nan)
    np.testing.assert_allclose(measure.anchor_ranges(), distances, rtol=1e-12)


def read_pty_lines(path, enough, timeout=60.0):
    """Read lines from a pty until ``enough(lines)`` or ``timeout`` seconds; return them."""
    import time
    reader = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    data, deadline = b'', time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            try:
                data += os.read(reader, 65536)
            except BlockingIOError:
                time.sleep(0.05)
            lines = data.decode(errors='replace').splitlines()
            if enough(lines):
                break
    finally:
        os.close(reader)
    return [line for line in data.decode(errors='replace').splitlines() if line]


def test_trek_emulator_prints_a_survey_burst_before_the_boom_moves(tmp_path):
    import yaml
    from epp_ros.app.config import default_config_path
    document = yaml.safe_load(default_config_path().read_text())
    document['/**']['ros__parameters'].update(
        anchor_names=['a0', 'a1', 'a2', 'a3'], anchor_ids=['0', '1', '2', '3'],
        body_anchors=['a0'],
        anchor_positions=[0.0, 0.0, 3.5, 2.6, 3.4, 0.4, 2.6, -3.4, 0.4, -4.2, 3.0, 0.6])
    config = tmp_path / 'trek.yaml'
    config.write_text(yaml.safe_dump(document))
    emulator = subprocess.Popen([console_script('uwb_emulator'), '--protocol', 'trek', '--pty',
                                 '--sigma', '0', '--config', str(config)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        announced = emulator.stdout.readline().split()
        assert announced[:1] == ['PTY'], emulator.stderr.read()
        lines = read_pty_lines(announced[1], lambda lines: sum(
            line.startswith('ma ') for line in lines[:-1]) > 11)
    finally:
        emulator.terminate()
        emulator.communicate(timeout=30)
    kinds = [line.split()[0] for line in lines]
    from epp_ros.uwb.emulation import SURVEY_BURST
    assert kinds[:SURVEY_BURST] == ['ma'] * SURVEY_BURST and kinds[SURVEY_BURST] != 'ma'
    # Then one round a second: after 10 more cycles of 5 tags' mr and mc lines each.
    later = [index for index, kind in enumerate(kinds) if kind == 'ma'][SURVEY_BURST:]
    assert later[:2] == [SURVEY_BURST + 100, SURVEY_BURST + 201]
    model = load_pump_config(config).model()
    distance = np.linalg.norm(model.anchors[0] - model.anchors[1])
    assert int(lines[0].split()[3], 16) == round(1000 * distance)
