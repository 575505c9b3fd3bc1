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

"""epp_calibrate end to end on synthesized bags, and the calibration bench."""
from dataclasses import replace
import json
import math
import subprocess
import sys

from benchmarks import calibration_bench
from epp_ros.app import bags
from epp_ros.app.config import load_pump_config
from epp_ros.cli import bag as bag_tool
from epp_ros.cli import calibrate as tool
from epp_ros.core.simulation.simulate import FieldEffects, FieldSimulator, StillMotion
import numpy as np
import pytest
from ros_processes import PUMP_YAML, script
import yaml

CONFIG = load_pump_config(PUMP_YAML)
#: Seconds a calibration may take on a slow, loaded machine: it bounds a hang, not a speed.
TIMEOUT = 900


@pytest.fixture(scope='module')
def good_bag(tmp_path_factory):
    """
    60 s of a working cycle with offsets and moved anchors, low noise: calibratable.

    Links may have offsets of their own too, which leaves the tip's link offsets known to
    +-4 cm after 30 s of this cycle (the tip's pitch hides them), +-2.5 cm after 60 s.
    """
    path = tmp_path_factory.mktemp('bags') / 'field'
    assert bag_tool.main(['synth', str(path), '--field', 'offsets,anchors_moved,sigma_low',
                          '--duration', '60', '--start', '1000', '--seed', '0']) == 0
    return path


@pytest.fixture(scope='module')
def calibrated(good_bag, tmp_path_factory):
    """Run epp_calibrate on the good bag; return its exit status, output and files."""
    folder = tmp_path_factory.mktemp('calibrated')
    out, plot = folder / 'calibrated.yaml', folder / 'calibration.png'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(good_bag),
                             '--config', str(PUMP_YAML), '--out', str(out),
                             '--fixed-anchors', 'turret', '--plot', str(plot), '--json'],
                            capture_output=True, text=True, timeout=TIMEOUT)
    return result, out, plot


def parked_bag(path, seconds):
    """Write a bag of a boom that does not move, with offsets."""
    model = CONFIG.model()
    simulator = FieldSimulator(model, FieldEffects(sigma=0.1, tag_offset=0.1,
                                                   anchor_offset=0.1),
                               np.random.default_rng(1))
    motion = StillMotion(model, 0.4, np.radians([55.0, 30.0, 5.0, -20.0, -45.0]))

    def cycles():
        for index in range(int(seconds * 10)):
            frame = simulator.frame(motion, 0.1 * index)
            yield 10 ** 12 + index * 10 ** 8, frame.ranges, frame.joints, None
    bags.write_cycles(path, CONFIG, cycles())
    return path


def test_calibrates_a_synthesized_bag_and_writes_a_config_the_nodes_load(calibrated):
    result, out, plot = calibrated
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    assert 'Verdict: ok' in result.stdout and f'wrote {out}' in result.stdout
    assert 'the first anchor' not in result.stdout     # named: no default to explain
    assert plot.stat().st_size > 10000
    printed = json.loads(result.stdout.strip().splitlines()[-1])
    assert printed['status'] == 'ok' and printed['written'] == str(out)
    assert printed['rms_after_m'] < 0.05 < printed['rms_before_m']
    config = load_pump_config(out)
    model = config.model()
    after = np.array([printed['anchors'][name]['after'] for name in config.anchor_names])
    np.testing.assert_allclose(model.anchors, after, atol=1e-6)
    np.testing.assert_allclose(model.anchor_offsets, [printed['anchor_offsets'][name]['after']
                                                      for name in config.anchor_names],
                               atol=1e-6)
    np.testing.assert_allclose(model.tag_offsets, [printed['tag_offsets'][name]['after']
                                                   for name in config.tag_names], atol=1e-6)
    np.testing.assert_allclose(model.link_offsets(), printed['link_offsets'], atol=2e-6)
    # The table shows the same numbers, to the millimetre.
    row = next(line for line in result.stdout.splitlines()
               if line.strip().startswith('outrigger_fl'))
    shown = [float(v) for v in row.split('->')[1].split(')')[0].strip(' (').split(',')]
    np.testing.assert_allclose(shown, model.anchors[1], atol=5e-4)
    # Everything else of the pump.yaml kept, comments too.
    source, written = yaml.safe_load(PUMP_YAML.read_text()), yaml.safe_load(out.read_text())
    # With each link's own offset, and what is left unknown for the estimator.
    parameters = written['/**']['ros__parameters']
    np.testing.assert_allclose(np.reshape(parameters['pair_offsets'], (5, 6)),
                               printed['pair_offsets'], atol=1e-6)
    for name in ('link_bias_std', 'common_bias_std', 'anchor_std'):
        assert abs(parameters[name] - printed[name]) <= 1e-6
        assert 0.0 < parameters[name] < 0.05
    # Each link's own, as printed; link_bias_std is their RMS; the estimator gets each.
    per_link = np.reshape(parameters['link_offset_std'], (5, 6))
    np.testing.assert_allclose(per_link, printed['link_offset_std'], atol=1e-6)
    assert abs(np.sqrt(np.mean(per_link ** 2)) - parameters['link_bias_std']) <= 2e-6
    np.testing.assert_allclose(config.with_link_biases({})['link_bias_std'], per_link)
    # anchor_std: the largest std of a located anchor, as printed.
    located = np.array([anchor['std'] for anchor in printed['anchors'].values()])
    assert abs(parameters['anchor_std'] - located.max()) <= 1e-6
    for name in ('anchor_positions', 'anchor_offsets', 'tag_offsets', 'pair_offsets',
                 'link_offset_std', 'link_bias_std', 'common_bias_std', 'anchor_std'):
        source['/**']['ros__parameters'].pop(name, None)
        written['/**']['ros__parameters'].pop(name)
    assert written == source
    assert '# posture_estimator' in out.read_text()


@pytest.mark.parametrize('node', ['posture_estimator', 'uwb_driver'])
def test_both_nodes_start_from_the_written_config(calibrated, node, listener, processes):
    _, out, _ = calibrated
    started = processes([script(node), '--ros-args', '--params-file', str(out)])
    assert listener.spin_until(lambda: listener.statuses(node) or started.poll() is not None,
                               30), node
    assert started.poll() is None, started.stderr.read()


def test_a_parked_boom_gives_one_line_and_writes_nothing(tmp_path):
    bag = parked_bag(tmp_path / 'parked', 12.0)
    out = tmp_path / 'calibrated.yaml'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                             '--config', str(PUMP_YAML), '--out', str(out),
                             '--fixed-anchors', 'turret,cab'],
                            capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('epp_calibrate: '), result.stderr
    assert 'poorly_excited' in lines[0] or 'cannot calibrate' in lines[0]
    assert 'slew' in lines[0] and not out.exists()


def test_a_poorly_exciting_recording_writes_only_with_force(tmp_path, capsys):
    bag = tmp_path / 'short_cycle'
    assert bag_tool.main(['synth', str(bag), '--field', 'offsets,anchors_moved,sigma_low',
                          '--duration', '20', '--start', '1000', '--seed', '0']) == 0
    capsys.readouterr()
    out = tmp_path / 'calibrated.yaml'
    arguments = [str(bag), '--config', str(PUMP_YAML), '--out', str(out), '--fixed-anchors',
                 'turret']
    assert tool.main(arguments) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and 'poorly_excited' in lines[0], captured.err
    assert 'nothing written' in captured.out and not out.exists()
    # --force writes it, and says why that is risky.
    assert tool.main(arguments + ['--force']) == 0
    assert 'warning: --force' in capsys.readouterr().err
    load_pump_config(out)
    # The lengths too with --fit-arm-lengths, as well as 20 s determine them: written.
    assert tool.main(arguments + ['--force', '--fit-arm-lengths', '--json']) == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    lengths = printed['arm_lengths']
    assert all(std > 0 for std in lengths['std']) and lengths['before'] == [9, 7, 7, 9, 9]
    np.testing.assert_allclose(load_pump_config(out).model().arm_lengths, lengths['after'],
                               atol=1e-6)


def test_a_short_recording_gives_one_line_and_writes_nothing(tmp_path):
    bag = parked_bag(tmp_path / 'short', 3.0)
    out = tmp_path / 'calibrated.yaml'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                             '--config', str(PUMP_YAML), '--out', str(out)],
                            capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and '30 frames' in lines[0] and 'nothing written' in lines[0]
    assert not out.exists()


@pytest.mark.parametrize('case', ['no_topic', 'no_bag', 'bad_anchor'])
def test_errors_are_one_line(tmp_path, case):
    bag = tmp_path / 'bag'
    arguments = [str(bag), '--config', str(PUMP_YAML), '--out', str(tmp_path / 'out.yaml')]
    if case == 'no_topic':
        message = bags.TYPESTORE.types['std_msgs/msg/String'](data='hello')
        bags.write_raw(bag, [('/chatter', 'std_msgs/msg/String', 1000,
                              bags.TYPESTORE.serialize_cdr(message, 'std_msgs/msg/String'),
                              None)])
        says = 'no /uwb/ranges topic'
    elif case == 'no_bag':
        says = 'no such bag'
    else:
        parked_bag(bag, 1.0)
        arguments += ['--fixed-anchors', 'turret,boom']
        says = "'boom' is not an anchor"
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', *arguments],
                            capture_output=True, text=True, timeout=TIMEOUT)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert says in lines[0] and lines[0].startswith('epp_calibrate: ')
    assert not (tmp_path / 'out.yaml').exists()


def test_fixed_anchors_by_name_or_id_and_the_default_said():
    assert tool.fixed_anchor_indices(CONFIG, 'turret, 1787')[0] == (0, 5)
    # A config that does not say which anchors are on the truck body: the first, said so.
    indices, note = tool.fixed_anchor_indices(replace(CONFIG, body_anchors=None), None)
    assert indices == (0,) and 'turret' in note and '--fixed-anchors' in note
    # The packaged one names them.
    indices, note = tool.fixed_anchor_indices(CONFIG, None)
    assert indices == (0, 5) and 'body_anchors' in note


def test_calibration_bench_runs_small():
    report = calibration_bench.run(seconds=10.0, seeds=1, seed=0, cases=('both',))
    assert report['suite'] == 'calibration' and len(report['rows']) == 1
    row = report['rows'][0]
    for key in ('anchor_m', 'link_offset_m', 'seconds', 'rms_before_m', 'rms_after_m',
                'chain configured', 'chain calibrated', 'track configured',
                'track calibrated'):
        assert math.isfinite(row[key]) and row[key] >= 0, key
    assert row['status'] in ('ok', 'poorly_excited', 'not_converged')
    assert 'chain calibrated' in calibration_bench.markdown(report)


def test_a_bag_without_anchor_ranges_says_so_and_calibrates_as_before(calibrated):
    result, _, _ = calibrated
    assert 'Anchor self-survey: none (no /uwb/anchor_ranges in the bag)' in result.stdout
    assert json.loads(result.stdout.strip().splitlines()[-1])['survey_rounds'] == 0


SURVEY_FIELD = 'offsets,anchors_moved,sigma_low'
SURVEY_SECONDS = 60.0


@pytest.fixture(scope='module')
def surveyed_bag(tmp_path_factory):
    """Write 60 s of a working cycle with anchor-anchor ranges (a start-up burst, then 1 Hz)."""
    path = tmp_path_factory.mktemp('bags') / 'surveyed'
    assert bag_tool.main(['synth', str(path), '--field', SURVEY_FIELD, '--duration',
                          str(SURVEY_SECONDS), '--start', '1000', '--seed', '0',
                          '--anchor-ranges']) == 0
    return path


def true_anchors(seconds, seed):
    """Where synth's field simulator put the anchors (the motion is drawn first, as synth)."""
    from epp_ros.core.simulation.simulate import field_effects, make_motion
    model = CONFIG.model()
    rng = np.random.default_rng(seed)
    make_motion('working', model, seconds, rng)
    effects = replace(field_effects(SURVEY_FIELD), moving_anchors=CONFIG.moving_anchor_indices)
    return FieldSimulator(model, effects, rng, 0.1).true_anchors


def turned_to(truth, anchors, base):
    """
    Return ``truth`` turned about the slew axis (vertical, through ``base``) onto ``anchors``.

    With the turret the only fixed anchor, a turn of every free anchor about the slew axis
    changes no range (calibrate's gauge): only the anchors' places relative to each other
    and to the axis can be compared with the truth. The turn is the least-squares one.
    """
    truth_xy, anchors_xy = truth[:, :2] - base[:2], anchors[:, :2] - base[:2]
    angle = np.arctan2(np.sum(truth_xy[:, 0] * anchors_xy[:, 1]
                              - truth_xy[:, 1] * anchors_xy[:, 0]),
                       np.sum(truth_xy * anchors_xy))
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    turned = truth.copy()
    turned[:, :2] = truth_xy @ turn.T + base[:2]
    return turned


def calibrate_json(bag, out, *extra):
    """Run epp_calibrate in-process; return its exit status, its JSON result and its lines."""
    import contextlib
    import io
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        status = tool.main([str(bag), '--config', str(PUMP_YAML), '--out', str(out),
                            '--fixed-anchors', 'turret', '--json', *extra])
    lines = stdout.getvalue().strip().splitlines()
    return status, json.loads(lines[-1]), lines


def test_anchor_ranges_self_survey_the_anchors(surveyed_bag, tmp_path):
    from epp_ros.uwb.emulation import SURVEY_BURST
    rounds = SURVEY_BURST + int(SURVEY_SECONDS) - 1
    surveyed = calibrate_json(surveyed_bag, tmp_path / 'surveyed.yaml')
    # Written with --force without the survey, to compare.
    ignored = calibrate_json(surveyed_bag, tmp_path / 'ignored.yaml', '--no-survey', '--force')
    assert surveyed[0] == 0 and surveyed[1]['status'] == 'ok', surveyed[2][-3:]
    assert surveyed[1]['survey_rounds'] == rounds and ignored[1]['survey_rounds'] == 0
    assert f'Anchor self-survey: yes, {rounds} rounds of /uwb/anchor_ranges (30 anchor ' \
        f'pairs, {rounds * 30} ranges)' in surveyed[2]
    assert 'Anchor self-survey: off (--no-survey: /uwb/anchor_ranges ignored)' in ignored[2]
    truth, base = true_anchors(SURVEY_SECONDS, 0), CONFIG.model().base
    errors, stds = {}, {}
    for label, (_, printed, _) in (('surveyed', surveyed), ('ignored', ignored)):
        written = load_pump_config(tmp_path / f'{label}.yaml').model().anchors
        errors[label] = np.linalg.norm(written - turned_to(truth, written, base), axis=1)[1:]
        stds[label] = np.array([np.linalg.norm(printed['anchors'][name]['std'])
                                for name in CONFIG.anchor_names[1:]])
    # Each surveyed anchor where its reported uncertainty says: within 4 times the norm of
    # its per-axis std (a 3-D error beyond that has a chance of about 1e-3), 1 mm for the
    # turn and rounding.
    assert (errors['surveyed'] <= 4 * stds['surveyed'] + 1e-3).all(), (errors, stds)
    # The survey adds information: every anchor is more certain, and closer to the truth
    # than without, up to twice the survey's own reported uncertainty (RMS over anchors).
    assert (stds['surveyed'] < stds['ignored']).all(), stds
    assert np.sqrt(np.mean(errors['surveyed'] ** 2)) <= np.sqrt(np.mean(
        errors['ignored'] ** 2)) + 2 * np.sqrt(np.mean(stds['surveyed'] ** 2)), (errors, stds)


def test_unreadable_anchor_ranges_give_one_line(tmp_path):
    source = parked_bag(tmp_path / 'parked', 12.0)
    wrong = bags.TYPESTORE.types['std_msgs/msg/String'](data='ma 0e')
    bag = tmp_path / 'retyped'
    bags.write_raw(bag, bags.read_all(source)[0] + [
        (bags.ANCHOR_RANGES, 'std_msgs/msg/String', 10 ** 12,
         bags.TYPESTORE.serialize_cdr(wrong, 'std_msgs/msg/String'), None)])
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                             '--config', str(PUMP_YAML)], capture_output=True, text=True,
                            timeout=TIMEOUT)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert 'holds std_msgs/msg/String, expected sensor_msgs/msg/JointState' in lines[0]


def test_the_noise_settings_follow_the_nodes_and_learn_the_noise_by_default():
    document = yaml.safe_load(PUMP_YAML.read_text())
    settings = tool.noise_settings(document)
    assert settings['learn_noise'] is True
    document['/**']['ros__parameters']['learn_noise'] = False
    assert tool.noise_settings(document)['learn_noise'] is False
    document['/**']['ros__parameters']['learn_noise'] = 'yes'
    with pytest.raises(tool.CalibrationError, match='learn_noise'):
        tool.noise_settings(document)


def rewritten(source, path, change):
    """Copy a bag, each /uwb/ranges message's positions passed through ``change``."""
    messages = []
    for topic, msgtype, stamp, raw, extra in bags.read_all(source)[0]:
        if topic == bags.RANGES:
            message = bags.TYPESTORE.deserialize_cdr(raw, msgtype)
            message.position = np.asarray(change(np.array(message.position)), dtype=float)
            raw = bags.TYPESTORE.serialize_cdr(message, msgtype)
        messages.append((topic, msgtype, stamp, raw, extra))
    bags.write_raw(path, messages)
    return path


def test_ranges_nobody_could_measure_are_left_out_and_counted(tmp_path):
    source = parked_bag(tmp_path / 'parked', 12.0)
    rng = np.random.default_rng(3)
    marked = []

    def spoil(values):
        spoilt = rng.random(values.size) < 0.1
        spoilt[-1] = False                          # the frame number
        values[spoilt] = rng.choice([0.0, 1e300, 1000.0, -2.0], spoilt.sum())
        marked.append(spoilt)
        return values
    bag = rewritten(source, tmp_path / 'spoilt', spoil)
    window = tool.range_window(yaml.safe_load(PUMP_YAML.read_text()))
    assert window == (0.05, 200.0)
    recording = tool.read_ranges(bag, CONFIG, window)
    clean = tool.read_ranges(source, CONFIG, window)
    spoilt = np.concatenate(marked)
    assert recording.implausible == spoilt.sum() > 0 and clean.implausible == 0
    assert np.isnan(recording.ranges).sum() == np.isnan(clean.ranges).sum() + spoilt.sum()
    kept = np.isfinite(recording.ranges)
    np.testing.assert_array_equal(recording.ranges[kept], clean.ranges[kept])
    assert f'left out {spoilt.sum()} ranges outside [0.05, 200] m' in \
        recording.left_out(window)
    # Longer than the boom can reach is as implausible as beyond max_range.
    far = tool.read_ranges(bag, CONFIG, (0.05, 1e6))
    assert far.implausible == spoilt.sum() and clean.left_out(window) is None


@pytest.mark.parametrize('value', [0.0, 1000.0, 1e300])
def test_a_recording_of_implausible_ranges_is_refused_in_seconds(tmp_path, value):
    bag = rewritten(parked_bag(tmp_path / 'parked', 12.0), tmp_path / 'absurd',
                    lambda values: np.r_[np.full(len(values) - 1, value), values[-1:]])
    out = tmp_path / 'calibrated.yaml'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                             '--config', str(PUMP_YAML), '--out', str(out)],
                            capture_output=True, text=True, timeout=TIMEOUT)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert '0 frames with 6 or more plausible ranges (left out 3600 ranges outside ' \
        '[0.05, 200] m' in lines[0] and not out.exists()


def test_malformed_messages_are_skipped_and_counted(tmp_path):
    source = parked_bag(tmp_path / 'parked', 12.0)
    messages = bags.read_all(source)[0]
    short = bags.TYPESTORE.types['sensor_msgs/msg/JointState'](
        header=bags._header(10 ** 12, 'pump_base'), name=['boom1:turret'],
        position=np.array([1.0, 2.0]), velocity=np.zeros(0), effort=np.zeros(0))
    broken = [(bags.RANGES, bags.TYPES[bags.RANGES], 10 ** 12 + 5, bags._serialize(short),
               None),
              (bags.ANCHOR_RANGES, bags.TYPES[bags.ANCHOR_RANGES], 10 ** 12 + 5,
               bags._serialize(short), None),
              (bags.ANCHOR_RANGES, bags.TYPES[bags.ANCHOR_RANGES], 10 ** 12 + 6,
               bags._serialize(replace(short, name=['turret:cab'], position=np.array([5.0]))),
               None)]
    bag = tmp_path / 'broken'
    bags.write_raw(bag, messages + broken)
    window = (0.05, 200.0)
    recording = tool.read_ranges(bag, CONFIG, window)
    assert recording.malformed == 1 and '1 names but 2 ranges' in recording.first_malformed
    assert len(recording.ranges) == len(recording.stamps) == 120
    np.testing.assert_array_equal(recording.ranges,
                                  tool.read_ranges(source, CONFIG, window).ranges)
    # The whole anchor round is used, the malformed one counted, both said in one line.
    rounds, line = tool.read_survey(bag, CONFIG, window)
    assert rounds.shape == (1, 6, 6) and rounds[0, 0, 5] == 5.0
    assert 'left out 1 malformed messages (the first: 1 names but 2 ranges)' in line
    # A topic whose labels name no anchors of the config: refused, naming --no-survey.
    alien = tmp_path / 'alien'
    bags.write_raw(alien, messages + [
        (bags.ANCHOR_RANGES, bags.TYPES[bags.ANCHOR_RANGES], 10 ** 12 + 5,
         bags._serialize(replace(short, name=['a:b'], position=np.array([5.0]))), None)])
    with pytest.raises(bags.BagError, match='--no-survey'):
        tool.read_survey(alien, CONFIG, window)
    assert tool.read_survey(alien, CONFIG, window, ignore=True)[0] is None


def test_unwritable_outputs_are_refused_before_the_bag_is_read(tmp_path):
    import os
    bag = tmp_path / 'no_such_bag'
    folder = tmp_path / 'a_bag'
    bags.synthesize(folder, CONFIG, duration=1.0)
    fifo = tmp_path / 'fifo.yaml'
    os.mkfifo(fifo)
    for extra, says in (
            (['--out', str(tmp_path)], 'is a folder'),
            (['--out', str(fifo)], 'is not a regular file'),
            (['--out', str(folder / 'metadata.yaml')], 'is a rosbag2 folder'),
            (['--out', str(tmp_path / 'missing' / 'x.yaml')], 'not a folder this user can'),
            (['--plot', str(tmp_path / 'missing' / 'x.png')], 'not a folder this user can'),
            (['--plot', str(tmp_path / 'x.unknown')], 'not one of the image types')):
        result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                                 '--config', str(PUMP_YAML), *extra],
                                capture_output=True, text=True, timeout=TIMEOUT)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, (extra, result.stderr)
        assert says in lines[0] and 'no such bag' not in lines[0], (extra, lines)
    # Inside the bag read, whatever the folder holds.
    inside = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(folder),
                             '--config', str(PUMP_YAML), '--out', str(folder / 'x.yaml')],
                            capture_output=True, text=True, timeout=TIMEOUT)
    assert inside.returncode == 2 and 'which is read' in inside.stderr, inside.stderr
    assert fifo.is_fifo() and sorted(p.name for p in folder.iterdir()) == \
        ['a_bag.mcap', 'metadata.yaml']


def configured_result():
    """Return a calibration result that says what the config says (write_config's input)."""
    from types import SimpleNamespace
    model = CONFIG.model()
    return SimpleNamespace(anchors=model.anchors, anchor_offsets=model.anchor_offsets,
                           tag_offsets=model.tag_offsets, pair_offsets=model.pair_offsets,
                           link_bias_stds=np.full((5, 6), 0.01),
                           left_unknown={'link_bias_std': 0.01, 'common_bias_std': 0.02,
                                         'anchor_std': 0.03}, arm_length_std=np.zeros(5),
                           arm_lengths=model.arm_lengths)


def test_the_written_config_keeps_its_link_and_permissions(tmp_path):
    import os
    import stat
    real = tmp_path / 'configs' / 'pump.yaml'
    real.parent.mkdir()
    real.write_text(PUMP_YAML.read_text())
    real.chmod(0o640)
    link = tmp_path / 'pump.yaml'
    link.symlink_to(real)
    tool.write_config(link, PUMP_YAML.read_text(), configured_result())
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert stat.S_IMODE(real.stat().st_mode) == 0o640
    assert 'link_bias_std: 0.01' in real.read_text()
    assert sorted(p.name for p in real.parent.iterdir()) == ['pump.yaml']
    # A new file gets what the umask gives, not mkstemp's 0600.
    umask = os.umask(0o027)
    try:
        tool.write_config(tmp_path / 'new.yaml', PUMP_YAML.read_text(), configured_result())
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / 'new.yaml').stat().st_mode) == 0o640
    load_pump_config(tmp_path / 'new.yaml')


def test_wild_ranges_are_found_and_a_moving_booms_are_not(good_bag):
    from epp_ros.core.model.measurements import range_spikes
    ranges = tool.read_ranges(good_bag, CONFIG, (0.05, 200.0)).ranges
    # 60 s of a working cycle at 10 Hz, offsets and all: no range a wild one.
    assert np.isfinite(ranges).sum() > 15000 and not range_spikes(ranges).any()
    rng = np.random.default_rng(4)
    wild = (rng.random(ranges.shape) < 0.05) & np.isfinite(ranges)
    spoilt = ranges.copy()
    spoilt[wild] += rng.choice([-1, 1], wild.sum()) * rng.uniform(1.5, 80.0, wild.sum())
    found = range_spikes(spoilt)
    assert not (wild & ~found).any()
    # A good range is taken for wild only when three of its four neighbours are:
    # P ~ 4 * 0.05**3 = 5e-4, ~8 of 15,000; four times that bounds it.
    assert (found & ~wild).sum() <= 4 * 5e-4 * np.isfinite(ranges).sum()
