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

"""epp_bag and epp_ros.app.bags: round trips, live replay, and broken bags."""
from dataclasses import replace
import json
from pathlib import Path
import signal
import subprocess
import time

from epp_ros.app import bags, contract
from epp_ros.app.config import load_pump_config
from epp_ros.core import METHODS
from epp_ros.nodes.messages import to_seconds
import numpy as np
import pytest
from ros_processes import PUMP_YAML, script

CONFIG = load_pump_config(PUMP_YAML)
pytestmark = pytest.mark.usefixtures('fresh_listener')


def epp_bag(*args, timeout=60):
    return subprocess.run([script('epp_bag'), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_synth_then_eval(storage, tmp_path):
    bag = tmp_path / 'cycle'
    result = epp_bag('synth', bag, '--storage', storage, '--duration', '8', '--sigma', '0.1',
                     '--seed', '3', '--raw', 'json')
    assert result.returncode == 0, result.stderr
    summary = bags.info(bag)
    assert summary['storage'] == storage and summary['duration_s'] == pytest.approx(7.9)
    counts = {t['topic']: t['count'] for t in summary['topics']}
    assert counts == {bags.RANGES: 80, bags.TRUTH: 80, bags.RAW: 400}
    assert 'metadata.yaml' in {p.name for p in bag.iterdir()}
    assert 'version: 9' in (bag / 'metadata.yaml').read_text()
    plot = tmp_path / 'error.png'
    report = epp_bag('eval', bag, '--method', 'chain', '--json', '--plot', plot)
    assert report.returncode == 0, report.stderr
    assert plot.read_bytes()[:4] == b'\x89PNG'
    result = json.loads(report.stdout.strip().splitlines()[-1])
    assert result['frames'] == 80 and result['method'] == 'chain'
    assert 0.05 < result['rmse_m'] < 0.5 and result['max_arm_length_error_m'] < 1e-9
    assert result['ms_per_frame'] > 0
    info = epp_bag('info', bag)
    assert 'Count: 80' in info.stdout and bags.RANGES in info.stdout


def test_eval_out_adds_the_estimated_posture(tmp_path):
    bags.synthesize(tmp_path / 'in', CONFIG, duration=3.0, drop=0.6, seed=4)
    result = bags.evaluate(tmp_path / 'in', CONFIG, 'cepp', out=tmp_path / 'out')
    assert 0 < result['solved'] < result['frames']          # sparse frames are skipped
    counts = {t['topic']: t['count'] for t in bags.info(tmp_path / 'out')['topics']}
    assert counts[bags.POSTURE] == result['solved'] and counts[bags.RANGES] == 30
    with bags._Bag(tmp_path / 'out') as bag:
        postures = list(bag.messages(bags.POSTURE, bags.TYPES[bags.POSTURE]))
    assert all(len(m.poses) == 6 and np.isfinite(m.poses[5].position.z) for _, m in postures)


def test_broken_bags_give_one_error_line(tmp_path):
    bag = tmp_path / 'cycle'
    bags.synthesize(bag, CONFIG, duration=5.0)
    mcap = next(bag.glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[:len(mcap.read_bytes()) // 2])      # truncated
    for target, expected in ((tmp_path / 'missing', 'no such bag'), (bag, 'cycle')):
        result = epp_bag('eval', target)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert result.returncode == 2 and len(lines) == 1 and expected in lines[0]


def test_missing_topic_and_other_message_types_are_refused(tmp_path):
    truth_only = tmp_path / 'truth_only'
    source = tmp_path / 'source'
    bags.synthesize(source, CONFIG, duration=2.0)
    bags.write_raw(truth_only, [m for m in bags.read_all(source)[0] if m[0] == bags.TRUTH])
    result = epp_bag('eval', truth_only)
    assert result.returncode == 2 and 'no /uwb/ranges topic' in result.stderr
    retyped = tmp_path / 'retyped'
    bags.write_raw(retyped, [(bags.RANGES, 'std_msgs/msg/String', 1, bags._serialize(
        bags.TYPESTORE.types['std_msgs/msg/String'](data='hello')), None)])
    result = epp_bag('eval', retyped)
    assert result.returncode == 2 and 'expected sensor_msgs/msg/JointState' in result.stderr


def decoded(path, topic):
    with bags._Bag(path) as bag:
        return [m for _, m in bag.messages(topic, bags.TYPES[topic])]


def test_play_then_record_gives_identical_messages(tmp_path, processes):
    source = tmp_path / 'source'
    bags.synthesize(source, CONFIG, duration=5.0, seed=5)
    recording = tmp_path / 'recording'
    recorder = processes([script('epp_bag'), 'record', str(recording), '--topics',
                          bags.RANGES, bags.TRUTH])
    time.sleep(2.0)
    played = epp_bag('play', source, '--rate', '4', '--subscribers', '1')
    assert played.returncode == 0, played.stderr
    time.sleep(1.0)
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(20) == 0, recorder.stderr.read()
    for topic in (bags.RANGES, bags.TRUTH):
        original, copy = decoded(source, topic), decoded(recording, topic)
        assert len(copy) == len(original) == 50
        for a, b in zip(original, copy):
            assert a.header == b.header
            if topic == bags.RANGES:
                assert list(a.name) == list(b.name)
                np.testing.assert_array_equal(a.position, b.position)
            else:
                assert a.poses == b.poses


def test_record_and_play_stop_when_told_while_topics_flow(tmp_path, listener, processes):
    """It used to wait for the topics to fall silent before writing: never, at 10 Hz."""
    source = tmp_path / 'long'
    bags.synthesize(source, CONFIG, duration=300.0, sigma=0.1, seed=8)
    player = processes([script('epp_bag'), 'play', str(source), '--topics', bags.RANGES,
                        '--subscribers', '1'])
    timed = tmp_path / 'timed'
    recorder = processes([script('epp_bag'), 'record', str(timed), '--topics', bags.RANGES,
                          '--duration', '3'])
    assert recorder.wait(120) == 0, recorder.stderr.read()
    assert player.poll() is None            # still playing: the topic never fell silent
    assert bags.info(timed)['storage'] == 'mcap'
    # Without a duration, SIGTERM ends it and it writes what it took: ranges that reached
    # the listener after the recorder had subscribed reached the recorder too (reliable).
    stopped = tmp_path / 'stopped'
    recorder = processes([script('epp_bag'), 'record', str(stopped), '--topics', bags.RANGES])
    assert listener.spin_until(lambda: listener.count_subscribers(bags.RANGES) >= 2, 60)
    listener.ranges.clear()
    assert listener.spin_until(lambda: len(listener.ranges) >= 5, 60)
    recorder.send_signal(signal.SIGTERM)
    assert recorder.wait(60) == 0, recorder.stderr.read()
    assert bags.info(stopped)['messages'] >= 5
    # Ctrl-C stops the player, which is how a player is stopped: exit status 0.
    player.send_signal(signal.SIGINT)
    assert player.wait(60) == 0, player.stderr.read()
    assert 'stopped playing' in player.stdout.read()


#: A setting of every estimator setting but the sensors' names and the QoS, none its default.
ALTERED = {'method': 'chain', 'reset_after_failures': 7, 'publish_markers': False,
           'learn_noise': False, 'arm_length_warn': 0.08, 'arm_length_error': 0.6,
           'residual_warn': 0.6, 'residual_error': 2.5, 'predicted_rmse_warn': 0.6,
           'predicted_rmse_error': 2.5, 'range_sigma': 0.12, 'nlos_fraction': 0.15,
           'nlos_gamma': 1.2, 'tag_sigma': 0.11, 'pitch_sigma': 0.01, 'slew_sigma': 0.011,
           'lowest_joint': -0.8, 'link_bias_std': 0.05, 'common_bias_std': 0.2,
           'bias_slope_std': 0.008, 'anchor_std': 0.05, 'max_angular_rate': 0.5,
           'learn_anchors': True, 'angle_max_age': 0.3,
           'slew_name': 'slew_encoder'}


def altered_pump_yaml(path):
    """Write the packaged pump.yaml with every setting of :data:`ALTERED` changed."""
    import yaml
    from epp_ros.app.settings import SETTINGS
    assert set(SETTINGS) - set(ALTERED) == {'pitch_names', 'ranges_qos'}
    assert all(value != SETTINGS[name].default for name, value in ALTERED.items())
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters'].update(ALTERED)
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.parametrize('settings', ['packaged', 'altered'])
def test_play_into_the_live_estimator_equals_eval(settings, tmp_path, listener, processes):
    """The node and ``epp_bag eval --config`` read the same file alike, every setting."""
    bag = tmp_path / 'cycle'
    bags.synthesize(bag, CONFIG, duration=6.0, sigma=0.1, drop=0.1, seed=6)
    config = PUMP_YAML if settings == 'packaged' else altered_pump_yaml(tmp_path / 'pump.yaml')
    evaluated = epp_bag('eval', bag, '--config', config, '--out', tmp_path / 'evaluated',
                        '--json', timeout=300)
    assert evaluated.returncode == 0, evaluated.stderr
    expected = json.loads(evaluated.stdout.splitlines()[-1])
    assert expected['method'] == ('cepp' if settings == 'packaged' else 'chain')
    offline = {(m.header.stamp.sec, m.header.stamp.nanosec): m
               for m in decoded(tmp_path / 'evaluated', bags.POSTURE)}
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(config)])
    # The listener subscribes too: wait for the estimator as the second subscriber.
    assert listener.spin_until(lambda: listener.count_subscribers('/uwb/ranges') >= 2, 60)
    # The player must match the estimator, not only the listener, before it starts.
    player = processes([script('epp_bag'), 'play', str(bag), '--fast', '--topics',
                        bags.RANGES, '--subscribers', '2'])
    assert listener.spin_until(lambda: len(listener.postures) >= expected['solved'], 120)
    assert player.wait(60) == 0
    listener.spin_until(lambda: False, 1.0)             # nothing more may come
    assert len(listener.postures) == expected['solved'] > 0
    for live in listener.postures:
        key = (live.header.stamp.sec, live.header.stamp.nanosec)
        reference = offline[key]
        for a, b in zip(live.poses, reference.poses):
            np.testing.assert_allclose([a.position.x, a.position.y, a.position.z],
                                       [b.position.x, b.position.y, b.position.z], atol=1e-9)
    assert to_seconds(listener.postures[-1].header.stamp) > 0


def test_a_killed_recording_is_reindexed_up_to_its_last_whole_chunk(tmp_path, processes):
    """SIGKILL leaves no metadata.yaml and no MCAP footer: reindex recovers the chunks."""
    source = tmp_path / 'source'
    bags.synthesize(source, CONFIG, duration=300.0, seed=9)
    recording = tmp_path / 'killed'
    recorder = processes([script('epp_bag'), 'record', str(recording), '--topics',
                          bags.RANGES, bags.TRUTH])
    storage = recording / 'killed.mcap'
    deadline = time.monotonic() + 120
    while not storage.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    player = processes([script('epp_bag'), 'play', str(source), '--rate', '10',
                        '--subscribers', '1'])
    # Two whole chunks of a MiB each are on disk once the file is past 2.2 MiB.
    deadline = time.monotonic() + 600
    while storage.stat().st_size < 2.2 * 2 ** 20 and time.monotonic() < deadline:
        assert recorder.poll() is None and player.poll() is None
        time.sleep(0.05)
    recorder.send_signal(signal.SIGKILL)
    recorder.wait(60)
    player.send_signal(signal.SIGINT)
    assert not (recording / 'metadata.yaml').exists()
    refused = epp_bag('info', recording)
    assert refused.returncode == 2 and f'epp_bag reindex {recording}' in refused.stderr
    result = epp_bag('reindex', recording)
    assert result.returncode == 0 and result.stderr == '', result.stderr
    assert f'reindexed {recording}: ' in result.stdout
    original = {(m.header.stamp.sec, m.header.stamp.nanosec): m
                for m in decoded(source, bags.RANGES)}
    copy = decoded(recording, bags.RANGES)
    # A MiB holds ~730 cycles of ranges and truth: two chunks, more than a thousand.
    assert len(copy) > 1000 and len(decoded(recording, bags.TRUTH)) > 1000
    for message in copy:
        match = original[(message.header.stamp.sec, message.header.stamp.nanosec)]
        assert list(message.name) == list(match.name)
        np.testing.assert_array_equal(message.position, match.position)
    assert bags.check(recording).intact
    assert epp_bag('reindex', recording).returncode == 2       # nothing to reindex now


def test_reindex_refuses_what_it_cannot_recover_in_one_line(tmp_path):
    whole = tmp_path / 'whole'
    bags.synthesize(whole, CONFIG, duration=1.0)
    sqlite = tmp_path / 'sqlite'
    bags.synthesize(sqlite, CONFIG, duration=1.0, storage='sqlite3')
    (sqlite / 'metadata.yaml').unlink()
    foreign = tmp_path / 'foreign'
    foreign.mkdir()
    (foreign / 'foreign.mcap').write_bytes(b'not an mcap file at all')
    for bag, says in ((whole, 'has its metadata.yaml'), (sqlite, 'sqlite3'),
                      (foreign, 'not an MCAP file'), (tmp_path / 'none', 'no such bag')):
        with pytest.raises(bags.BagError, match=says):
            bags.reindex(bag)
        result = epp_bag('reindex', bag)
        assert result.returncode == 2 and len(result.stderr.splitlines()) == 1, result.stderr
    # Cut inside its first chunk, a bag keeps nothing, and says so.
    cut = tmp_path / 'cut'
    cut.mkdir()
    content = (whole / 'whole.mcap').read_bytes()
    (cut / 'cut.mcap').write_bytes(content[:last_chunk(content) + 100])
    counts, lost, stopped = bags.reindex(cut)
    assert counts == {} and lost > 0 and stopped is None
    assert bags.info(cut)['messages'] == 0


def last_chunk(content):
    """Return the offset of the last chunk record of an MCAP file (opcode 0x06)."""
    import struct
    at, found = 8, None                             # after the magic
    while at + 9 <= len(content):
        opcode, length = content[at], struct.unpack_from('<Q', content, at + 1)[0]
        found = at if opcode == 0x06 else found
        at += 9 + length
    return found


def damaged_copy(source, target, where, data):
    """
    Copy a bag and write ``data`` over its storage file at fraction ``where``.

    ``where='last chunk'``: over the last chunk's header. The chunks carry no CRC here, so
    zeros over a range's bytes are a valid range: damage is found where it breaks structure.
    """
    import shutil
    shutil.copytree(source, target)
    storage = next(path for path in target.iterdir() if path.suffix == '.mcap')
    content = bytearray(storage.read_bytes())
    at = last_chunk(content) if where == 'last chunk' else int(len(content) * where)
    content[at:at + len(data)] = data
    storage.write_bytes(bytes(content))
    return target


@pytest.mark.parametrize('where, data', [
    (0.5, np.random.default_rng(0).bytes(4096)), (0.3, bytes(64)), ('last chunk', bytes(64))],
    ids=['random-4k-middle', 'zeros-30%', 'zeros-last-chunk'])
def test_a_damaged_bag_is_refused_unless_salvaged(where, data, tmp_path):
    clean = tmp_path / 'clean'
    bags.synthesize(clean, CONFIG, duration=60.0, seed=4)
    damaged = damaged_copy(clean, tmp_path / 'damaged', where, data)
    damage = bags.check(damaged)
    assert not damage.intact and bags.check(clean).intact
    assert damage.expected == {bags.RANGES: 600, bags.TRUTH: 600}
    assert sum(damage.read.values()) < 1200
    for command in (['eval', str(damaged)], ['play', str(damaged), '--fast']):
        result = epp_bag(*command)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert result.returncode == 2 and len(lines) == 1, result.stderr
        assert 'damaged: read' in lines[0] and 'of 1200 messages' in lines[0]
    salvaged = epp_bag('eval', str(damaged), '--salvage', '--json')
    assert salvaged.returncode == 0, salvaged.stderr
    assert 'salvaged' in salvaged.stderr
    result = json.loads(salvaged.stdout.splitlines()[-1])
    assert result['frames'] == damage.read.get(bags.RANGES, 0) < 600
    assert result['damage'] == damage.describe()


def test_eval_refuses_an_existing_output_before_it_starts(tmp_path):
    """The output is checked first: before the bag is even opened, let alone evaluated."""
    (tmp_path / 'taken').mkdir()
    with pytest.raises(bags.BagError, match='taken exists already'):
        bags.evaluate(tmp_path / 'no_such_bag', CONFIG, 'chain', out=tmp_path / 'taken')


class SpyEstimator(bags.PostureEstimator):
    """A PostureEstimator that records what each frame gave it."""

    calls = []

    def update(self, ranges, **inputs):
        joints = super().update(ranges, **inputs)
        self.calls.append((inputs['stamp'], inputs.get('range_stamps'),
                           list(self.last_diagnostics['ignored_inputs'])))
        return joints


def frames_with_ages(count=5):
    """Return noiseless frames (stamp_ns, ranges) and their ages, tag k measured later."""
    model = CONFIG.model()
    pitches = np.radians([55.0, 30.0, 0.0, -20.0, -45.0])
    stamps = [1_000_000_000_000 + 100_000_000 * k for k in range(count)]
    ranges = [model.ranges(model.forward_kinematics(0.3 + 0.01 * k, pitches))
              for k in range(count)]
    ages = []
    for k in range(count):
        age = np.repeat(0.02 * np.arange(4, -1, -1.0)[:, None], 6, axis=1) + 0.001 * k
        age[0, 0] = np.nan                          # an unknown age: the others decide
        age[1, 2] = -1.0                            # a bad age: unknown too
        ages.append(age)
    return list(zip(stamps, ranges)), ages


@pytest.mark.parametrize('with_ages', [True, False])
def test_eval_gives_the_estimator_each_tags_measurement_time(with_ages, monkeypatch,
                                                             tmp_path):
    frames, ages = frames_with_ages()
    bag = tmp_path / 'aged'
    bags.write_frames(bag, CONFIG, frames, ages=ages if with_ages else None)
    stored = decoded(bag, bags.RANGES)
    assert [len(m.effort) for m in stored] == [31 if with_ages else 0] * len(frames)
    assert [contract.frame_number(m.name, m.position) for m in stored] == \
        list(range(1, len(frames) + 1))
    monkeypatch.setattr(SpyEstimator, 'calls', [])
    monkeypatch.setattr(bags, 'PostureEstimator', SpyEstimator)
    result = bags.evaluate(bag, CONFIG, 'chain')
    assert result['frames'] == len(SpyEstimator.calls) == len(frames) and result['solved']
    used = 'range_stamps' in METHODS['chain'].inputs
    for (stamp_ns, _), age, (stamp, range_stamps, ignored) in zip(frames, ages,
                                                                  SpyEstimator.calls):
        assert stamp == pytest.approx(stamp_ns * 1e-9, abs=1e-9)
        if not with_ages:
            assert range_stamps is None and 'range_stamps' not in ignored
            continue
        expected = stamp - np.array([np.median(row[np.isfinite(row) & (row >= 0)])
                                     for row in age])
        np.testing.assert_allclose(range_stamps, expected, atol=1e-9)
        assert range_stamps[0] < range_stamps[4] == pytest.approx(stamp, abs=0.01)
        assert ('range_stamps' in ignored) == (not used)


def test_ages_must_come_one_per_frame(tmp_path):
    frames, ages = frames_with_ages(3)
    with pytest.raises(ValueError):
        bags.write_frames(tmp_path / 'short', CONFIG, frames, ages=ages[:2])


def test_synth_writes_anchor_ranges_that_the_reader_returns(tmp_path):
    from epp_ros.core.simulation.simulate import field_effects, FieldSimulator, make_motion
    from epp_ros.uwb.emulation import SURVEY_BURST
    bag = tmp_path / 'surveyed'
    result = epp_bag('synth', bag, '--field', 'offsets,anchors_moved', '--duration', '3',
                     '--seed', '2', '--start', '1000', '--anchor-ranges')
    assert result.returncode == 0, result.stderr
    counts = {t['topic']: t['count'] for t in bags.info(bag)['topics']}
    assert counts == {bags.ANCHOR_RANGES: SURVEY_BURST + 2, bags.RANGES: 30, bags.TRUTH: 30}
    # The same simulator as synth's (the motion drawn first): its rounds, in order.
    model = CONFIG.model()
    rng = np.random.default_rng(2)
    make_motion('working', model, 3.0, rng)
    effects = replace(field_effects('offsets,anchors_moved'),
                      moving_anchors=CONFIG.moving_anchor_indices)   # the outriggers
    simulator = FieldSimulator(model, effects, rng, 0.1)
    expected = np.array([simulator.anchor_ranges() for _ in range(SURVEY_BURST + 2)])
    rounds = bags.read_anchor_ranges(bag, CONFIG)
    assert rounds.shape == (SURVEY_BURST + 2, 6, 6)
    np.testing.assert_array_equal(rounds, expected)
    assert np.isnan(rounds[:, range(6), range(6)]).all() and np.isfinite(rounds).sum() == 12 * 30
    # At the stamps of cycles 0 (the burst), 10 and 20, labelled measuring anchor first.
    stored = decoded(bag, bags.ANCHOR_RANGES)
    assert [m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec for m in stored] == \
        [1000 * 10 ** 9] * SURVEY_BURST + [1001 * 10 ** 9, 1002 * 10 ** 9]
    assert stored[0].name[:2] == ['turret:outrigger_fl', 'turret:outrigger_fr']
    assert len(stored[0].name) == 30 and stored[0].header.frame_id == CONFIG.frame_id
    # The tag ranges are drawn as without --anchor-ranges.
    plain = tmp_path / 'plain'
    assert epp_bag('synth', plain, '--field', 'offsets,anchors_moved', '--duration', '3',
                   '--seed', '2', '--start', '1000').returncode == 0
    for a, b in zip(decoded(bag, bags.RANGES), decoded(plain, bags.RANGES)):
        np.testing.assert_array_equal(a.position, b.position)


def test_anchor_ranges_reader_leaves_missing_pairs_nan_and_older_bags_empty(tmp_path):
    model = CONFIG.model()
    joints = model.forward_kinematics(0.3, np.radians([55.0, 30.0, 0.0, -20.0, -45.0]))
    first = np.full((6, 6), np.nan)
    first[0, 1], first[4, 2] = 5.5, 7.25
    second = np.full((6, 6), np.nan)
    second[5, 0] = 5.0

    def rounds(cycle):
        return [first, second] if cycle == 1 else []

    cycles = [(10 ** 12 + k * 10 ** 8, model.ranges(joints), joints, None) for k in range(3)]
    bag = tmp_path / 'partial'
    counts = bags.write_cycles(bag, CONFIG, cycles, anchor_rounds=rounds)
    assert counts[bags.ANCHOR_RANGES] == 2
    read = bags.read_anchor_ranges(bag, CONFIG)
    np.testing.assert_array_equal(read, [first, second])
    assert [list(m.name) for m in decoded(bag, bags.ANCHOR_RANGES)] == \
        [['turret:outrigger_fl', 'outrigger_rr:outrigger_fr'], ['cab:turret']]
    older = tmp_path / 'older'
    bags.synthesize(older, CONFIG, duration=1.0)
    assert bags.read_anchor_ranges(older, CONFIG).shape == (0, 6, 6)


def anchor_message(names, values):
    message = bags.TYPESTORE.types['sensor_msgs/msg/JointState'](
        header=bags._header(10 ** 12, 'pump_base'), name=names,
        position=np.array(values, dtype=np.float64), velocity=np.zeros(0),
        effort=np.zeros(0))
    return bags._serialize(message)


@pytest.mark.parametrize('msgtype, raw, says', [
    ('sensor_msgs/msg/JointState', anchor_message(['a:b', 'c:d'], [1.0, 2.0]),
     'no /uwb/anchor_ranges label names two anchors'),
    ('sensor_msgs/msg/JointState', anchor_message(['turret:cab'], [1.0, 2.0]),
     'malformed: 1 names but 2 ranges'),
    ('std_msgs/msg/String', bags._serialize(
        bags.TYPESTORE.types['std_msgs/msg/String'](data='ma 0e')),
     'holds std_msgs/msg/String, expected sensor_msgs/msg/JointState'),
])
def test_unusable_anchor_ranges_give_one_line(msgtype, raw, says, tmp_path):
    bag = tmp_path / 'bad'
    bags.write_raw(bag, [(bags.ANCHOR_RANGES, msgtype, 10 ** 12, raw, None)])
    with pytest.raises(bags.BagError, match=says):
        bags.read_anchor_ranges(bag, CONFIG)


def test_record_takes_anchor_ranges_by_default():
    from epp_ros.cli import bag as bag_tool
    assert bags.ANCHOR_RANGES == '/uwb/anchor_ranges'
    assert bags.ANCHOR_RANGES in bag_tool.DEFAULT_RECORD
    assert bags.TYPES[bags.ANCHOR_RANGES] == 'sensor_msgs/msg/JointState'
    assert bags.TOPIC_QOS[bags.ANCHOR_RANGES].depth == 100


def test_record_refuses_its_output_before_it_records(tmp_path):
    """An OUT that exists or cannot be written: one line at once, not after --duration."""
    (tmp_path / 'taken').mkdir()
    for out, says in ((tmp_path / 'taken', 'exists already'),
                      (Path('/proc/no/such/bag'), 'cannot write')):
        result = subprocess.run([script('epp_bag'), 'record', str(out), '--duration', '600'],
                                capture_output=True, text=True, timeout=120)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert result.returncode == 2 and len(lines) == 1, result.stderr
        assert says in lines[0] and str(out) in lines[0] and 'Traceback' not in lines[0]
