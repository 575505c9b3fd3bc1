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

"""epp_calibrate end to end on synthesized bags, the pump.yaml writer, the bench."""
import json
import math
import subprocess
import sys

from epp_ros import bags
from epp_ros.config import ConfigError, load_pump_config, update_pump_yaml
from epp_ros.core.simulate import FieldEffects, FieldSimulator, StillMotion
from epp_ros.tools import bag as bag_tool
from epp_ros.tools import calibrate as tool
from epp_ros.tools import calibration_bench
import numpy as np
import pytest
from system import PUMP_YAML, script
import yaml

CONFIG = load_pump_config(PUMP_YAML)


@pytest.fixture(scope='module')
def good_bag(tmp_path_factory):
    """30 s of a working cycle with offsets and moved anchors, low noise: calibratable."""
    path = tmp_path_factory.mktemp('bags') / 'field'
    assert bag_tool.main(['synth', str(path), '--field', 'offsets,anchors_moved,sigma_low',
                          '--duration', '30', '--start', '1000', '--seed', '0']) == 0
    return path


@pytest.fixture(scope='module')
def calibrated(good_bag, tmp_path_factory):
    """Run epp_calibrate on the good bag; return its exit status, output and files."""
    folder = tmp_path_factory.mktemp('calibrated')
    out, plot = folder / 'calibrated.yaml', folder / 'calibration.png'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.tools.calibrate', str(good_bag),
                             '--config', str(PUMP_YAML), '--out', str(out),
                             '--fixed-anchors', 'turret', '--plot', str(plot), '--json'],
                            capture_output=True, text=True, timeout=120)
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
    for name in ('anchor_positions', 'anchor_offsets', 'tag_offsets'):
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
    result = subprocess.run([sys.executable, '-m', 'epp_ros.tools.calibrate', str(bag),
                             '--config', str(PUMP_YAML), '--out', str(out),
                             '--fixed-anchors', 'turret,cab'],
                            capture_output=True, text=True, timeout=120)
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


def test_a_short_recording_gives_one_line_and_writes_nothing(tmp_path):
    bag = parked_bag(tmp_path / 'short', 3.0)
    out = tmp_path / 'calibrated.yaml'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.tools.calibrate', str(bag),
                             '--config', str(PUMP_YAML), '--out', str(out)],
                            capture_output=True, text=True, timeout=60)
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
    result = subprocess.run([sys.executable, '-m', 'epp_ros.tools.calibrate', *arguments],
                            capture_output=True, text=True, timeout=60)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert says in lines[0] and lines[0].startswith('epp_calibrate: ')
    assert not (tmp_path / 'out.yaml').exists()


def test_fixed_anchors_by_name_or_id_and_the_default_said():
    assert tool.fixed_anchor_indices(CONFIG, 'turret, 1787')[0] == (0, 5)
    indices, note = tool.fixed_anchor_indices(CONFIG, None)
    assert indices == (0,) and 'turret' in note and '--fixed-anchors' in note


def test_update_pump_yaml_keeps_the_file_and_replaces_the_values(tmp_path):
    text = PUMP_YAML.read_text()
    anchors = np.array(CONFIG.anchor_positions)
    anchors[1] += [0.1234567, -0.2, 0.05]
    updated = update_pump_yaml(text, {'anchor_positions': anchors.ravel().tolist(),
                                      'anchor_offsets': [0.1, 0.0, -0.05, 0.0, 0.2, 1e-9],
                                      'tag_offsets': [0.01, 0.02, 0.03, 0.04, -0.05]})
    # Only the values changed: every comment and setting line is still there.
    changed = set(text.splitlines()) - set(updated.splitlines())
    assert changed == {' ' * 23 + '2.6, 3.4, 0.4,'}
    path = tmp_path / 'pump.yaml'
    path.write_text(updated)
    model = load_pump_config(path).model()
    np.testing.assert_allclose(model.anchors, anchors, atol=1e-6)
    np.testing.assert_allclose(model.anchor_offsets, [0.1, 0.0, -0.05, 0.0, 0.2, 0.0])
    # Replacing again edits in place.
    again = update_pump_yaml(updated, {'tag_offsets': [0.0] * 5})
    assert again.count('\n    tag_offsets: [') == 1
    assert 'tag_offsets: [0.0, 0.0, 0.0, 0.0, 0.0]' in again
    with pytest.raises(ConfigError, match='anchor_offsets'):
        update_pump_yaml(text, {'anchor_offsets': [0.1]})
    with pytest.raises(ConfigError, match='unknown'):
        update_pump_yaml(text, {'anchors': [0.1]})


def test_calibration_bench_runs_small():
    report = calibration_bench.run(seconds=10.0, seeds=1, seed=0)
    assert report['suite'] == 'calibration' and len(report['rows']) == 1
    row = report['rows'][0]
    for key in ('anchor_m', 'link_offset_m', 'seconds', 'rms_before_m', 'rms_after_m',
                'chain configured', 'chain calibrated', 'track configured',
                'track calibrated'):
        assert math.isfinite(row[key]) and row[key] >= 0, key
    assert row['status'] in ('ok', 'poorly_excited', 'not_converged')
    assert 'chain calibrated' in calibration_bench.markdown(report)
