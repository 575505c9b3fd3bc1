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

"""uwb_emulator -> pty or TCP -> uwb_driver -> /uwb/ranges, as separate processes over DDS."""
import signal
import socket
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticStatus
from epp_ros.app.config import load_pump_config
from epp_ros.app.contract import FRAME_NUMBER
from epp_ros.nodes.messages import to_seconds
import numpy as np
import pytest
from ros_processes import (params_with_sources, poses_to_joints, PUMP_YAML, script, start_emulator,
                           truth_window)
import yaml

pytestmark = pytest.mark.usefixtures('fresh_listener')


#: Seconds: how long before its frame's stamp a range's cycle can have been, on a loaded
#: machine (a cycle, its ages, and a backlog read late).
TRUTH_LAG = 0.6


def checkable_frames(listener, since):
    """
    Return the range frames from ``since`` on whose cycles' truth was heard.

    Cycles whose truth was not heard: a restarted emulator's until its publisher is
    discovered again, and any a loaded listener lost (truth is keep-last). A frame whose
    ranges may come from one of them has no truth to match.
    """
    if not listener.truth:
        return []
    stamps = np.array([to_seconds(m.header.stamp) for m in listener.truth])
    # Three cycles after the first truth heard: the rows of earlier ones have none.
    first, last = stamps[0] + 0.3, stamps[-1]
    holes = [(stamps[i], stamps[i + 1]) for i in np.flatnonzero(np.diff(stamps) > 0.15)]

    def heard(stamp):
        return not any(before < stamp and after > stamp - TRUTH_LAG for before, after in holes)
    return [f for f in listener.ranges[since:]
            if first <= to_seconds(f.header.stamp) <= last and heard(to_seconds(f.header.stamp))]


def check_ranges_against_truth(listener, config, since, tolerance):
    """
    Check every tag's ranges in every frame against the true postures.

    Every tag's ranges in every frame must match the true postures (no noise) of one cycle
    or of two adjacent ones within the format's precision, and frames carry the configured
    names. (Tags on separate ports are not synchronised: one frame may hold rows of adjacent
    cycles. Where each range is its own line, a cycle closed by its ``frame_period`` on a
    loaded machine leaves its late lines to the next frame, beside that cycle's first ones.)
    Waits, generously, for three frames whose truth was heard: a loaded listener loses some.
    """
    checked = listener.ranges[min(since + 2, len(listener.ranges) - 1)]
    truth_window(listener, covering=to_seconds(checked.header.stamp))
    listener.spin_until(lambda: len(checkable_frames(listener, since)) >= 3, 30.0)
    listener.spin_until(lambda: False, 0.5)      # the truth of the newest cycle comes last
    frames = checkable_frames(listener, since)
    model = config.model()
    true_ranges = np.array([model.ranges(poses_to_joints(m)) for m in listener.truth])
    assert len(frames) >= 3
    for frame in frames:
        check_range_ages(frame)
        assert list(frame.name) == [*config.link_names, FRAME_NUMBER]
        assert frame.header.frame_id == config.frame_id
        assert abs(to_seconds(frame.header.stamp) - time.time()) < 30
        measured = np.array(frame.position[:-1]).reshape(model.n_sections, model.n_anchors)
        assert np.isfinite(measured).any()
        for row in np.flatnonzero(np.isfinite(measured).any(axis=1)):
            reported = np.isfinite(measured[row])
            matches = np.abs(true_ranges[:, row, reported] - measured[row, reported]) <= tolerance
            of_two_cycles = matches[:-1] | matches[1:]
            assert of_two_cycles.all(axis=1).any(), (row, measured[row])


def check_range_ages(frame, frame_period=0.1, slack=0.1):
    """Check one age (``effort``, s) per range: finite, >= 0 and within a cycle where it is."""
    ranges, ages = np.array(frame.position), np.array(frame.effort)
    assert ages.shape == ranges.shape
    if frame.name[-1] == FRAME_NUMBER:          # the frame's number, not a range
        assert ages[-1] == 0.0
        ranges, ages = ranges[:-1], ages[:-1]
    reported = np.isfinite(ranges)
    assert np.isfinite(ages[reported]).all() and np.isnan(ages[~reported]).all()
    assert (ages[reported] >= 0).all() and (ages[reported] < frame_period + slack).all()
    assert ages[reported].min() < 1e-3                  # the stamp is the newest range's


TREK_YAML = {
    'anchor_names': ['a0', 'a1', 'a2', 'a3'], 'anchor_ids': ['0', '1', '2', '3'],
    'anchor_positions': [0.0, 0.0, 3.5, 2.6, 3.4, 0.4, 2.6, -3.4, 0.4, -4.2, 3.0, 0.6],
    'tag_ids': ['1', '2', '3', '4', '5'], 'body_anchors': ['a0'],
}


def trek_config(tmp_path):
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters'].update(TREK_YAML)
    path = tmp_path / 'trek_pump.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.parametrize('protocol', ['json', 'lec', 'arduino', 'trek'])
def test_each_protocol_over_pty_reaches_uwb_ranges(protocol, listener, processes, tmp_path):
    config_path = trek_config(tmp_path) if protocol == 'trek' else PUMP_YAML
    config = load_pump_config(config_path)
    _, announced = start_emulator(processes, protocol, ['--pty'], config_path)
    params = params_with_sources(tmp_path, config_path, announced, protocol)
    since = len(listener.ranges)
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(params)])
    assert listener.spin_until(lambda: len(listener.ranges) >= since + 8, 15), \
        driver.stderr.read() if driver.poll() is not None else 'no frames'
    tolerance = {'json': 2e-3, 'lec': 6e-3, 'arduino': 6e-3, 'trek': 1.5e-3}[protocol]
    check_ranges_against_truth(listener, config, since + 2, tolerance)


def test_unplugged_pty_is_reconnected(listener, processes, tmp_path):
    link = str(tmp_path / 'ttyUWB')
    emulator, _ = start_emulator(processes, 'json', ['--pty', '--link', link])
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:={link}', '-p', 'protocol:=json'])
    # Generous waits: each returns as soon as its condition holds.
    assert listener.spin_until(lambda: len(listener.ranges) >= 3, 60)
    emulator.send_signal(signal.SIGINT)                      # unplug: the pty goes away
    emulator.wait(30)
    listener.diagnostics.clear()
    assert listener.spin_until(lambda: DiagnosticStatus.ERROR in [
        s.level for s in listener.statuses('uwb_driver')], 30)
    count = len(listener.ranges)
    start_emulator(processes, 'json', ['--pty', '--link', link])          # plug back in
    assert listener.spin_until(lambda: len(listener.ranges) >= count + 8, 60)
    assert driver.poll() is None
    check_ranges_against_truth(listener, load_pump_config(PUMP_YAML), count + 2, 2e-3)


def free_port():
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def test_tcp_bridge_path_survives_a_bridge_restart(listener, processes, tmp_path):
    port = free_port()
    emulator, announced = start_emulator(processes, 'json', ['--tcp', f'127.0.0.1:{port}'])
    assert announced[0][1] == f'socket://127.0.0.1:{port}'
    since = len(listener.ranges)
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:=socket://127.0.0.1:{port}', '-p', 'protocol:=auto'])
    assert listener.spin_until(lambda: len(listener.ranges) >= since + 5, 15)
    check_ranges_against_truth(listener, load_pump_config(PUMP_YAML), since + 2, 2e-3)
    emulator.send_signal(signal.SIGINT)
    emulator.wait(5)
    time.sleep(1.0)
    count = len(listener.ranges)
    start_emulator(processes, 'json', ['--tcp', f'127.0.0.1:{port}'])
    assert listener.spin_until(lambda: len(listener.ranges) >= count + 5, 15)
    assert driver.poll() is None


def test_garbage_is_counted_and_never_stops_the_driver(listener, processes, tmp_path):
    link = str(tmp_path / 'ttyNoisy')
    start_emulator(processes, 'json', ['--pty', '--link', link], extra=['--garbage', '0.3'])
    since = len(listener.ranges)
    listener.diagnostics.clear()
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:={link}', '-p', 'protocol:=json'])
    assert listener.spin_until(lambda: len(listener.ranges) >= since + 10, 15)

    def unparsed():
        values = [{kv.key: kv.value for kv in status.values}
                  for status in listener.statuses(f'uwb_driver: {link}')]
        return max((int(v['unparsed lines']) + int(v['parse errors']) for v in values),
                   default=0)

    assert listener.spin_until(lambda: unparsed() > 0, 5)
    assert driver.poll() is None


def test_bad_configuration_stops_the_driver_with_one_line(tmp_path):
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters']['anchor_ids'][2] = 'not-hex'
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(document))
    result = subprocess.run([script('uwb_driver'), '--ros-args', '--params-file', str(path)],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    message = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(message) == 1 and 'anchor_ids' in message[0] and 'Traceback' not in message[0]


def test_trek_with_more_than_four_anchors_is_refused_at_start():
    result = subprocess.run([script('uwb_driver'), '--ros-args', '--params-file',
                             str(PUMP_YAML), '-p', 'port:=/dev/null', '-p', 'protocol:=trek'],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2 and 'at most 4 anchors' in result.stderr


@pytest.mark.parametrize('executable, name, value, method', [
    ('uwb_driver', 'frame_period', 'fast', None),
    ('posture_estimator', 'residual_warn', [1.0], None),
    ('posture_estimator', 'method', 'magic', None),
    ('posture_estimator', 'method', 'tpsm', None),
    ('posture_estimator', 'nlos_fraction', 1.5, None),
    ('posture_estimator', 'range_sigma', 0.0, None),
    ('posture_estimator', 'range_sigma', float('inf'), None),
    ('posture_estimator', 'residual_warn', float('nan'), None),
    ('posture_estimator', 'reset_after_failures', 0, None),
    ('posture_estimator', 'anchor_positions', [1.0, 2.0, 3.0] * 6, None),
    ('uwb_driver', 'anchor_positions', [0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 3.0,
                                        0.0, 0.0, 4.0, 0.0, 0.0, 5.0, 0.0, 0.0, 6.0], None),
    ('posture_estimator', 'slew_sigma', -1.0, None),
    ('posture_estimator', 'pitch_names', ['pitch1', 'pitch2'], 'chain'),
    ('posture_estimator', 'angle_max_age', 0.0, 'chain'),
    ('posture_estimator', 'ranges_qos', 'fast', None),
])
def test_bad_settings_stop_a_node_with_one_line(executable, name, value, method, tmp_path):
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters'][name] = value
    if method is not None:
        document['/**']['ros__parameters']['method'] = method
    path = tmp_path / 'settings.yaml'
    path.write_text(yaml.safe_dump(document))
    result = subprocess.run([script(executable), '--ros-args', '--params-file', str(path)],
                            capture_output=True, text=True, timeout=30)
    message = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(message) == 1, result.stderr
    assert name in message[0] and 'Traceback' not in message[0]


def test_command_line_settings_override_the_file(listener, processes):
    """`-p method:=chain` must reach the estimator (a node section in the file would win)."""
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               '-p', 'method:=chain'])
    assert listener.spin_until(lambda: any(
        kv.key == 'method' and kv.value == 'chain' for status in
        listener.statuses('posture_estimator') for kv in status.values), 10)


def start_any_emulator(start, protocol, config):
    """Start uwb_emulator in any format; return it and its announced channels."""
    from epp_ros.uwb.emulation import channel_devices
    emulator = start([script('uwb_emulator'), '--protocol', protocol, '--pty', '--truth',
                      '--sigma', '0', '--rate', '10', '--config', str(config)])
    expected = len(channel_devices(protocol, load_pump_config(config)))
    announced = [emulator.stdout.readline().split() for _ in range(expected)]
    assert all(a and a[0] == 'PTY' for a in announced), emulator.stderr.read()
    return emulator, announced


def slot_config(tmp_path):
    """Return the packaged pump with anchors numbered 0-5, as the 8-slot formats print them."""
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters']['anchor_ids'] = ['0', '1', '2', '3', '4', '05']
    path = tmp_path / 'slot_pump.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.parametrize('protocol', ['haoru', 'les', 'mauwb_json'])
def test_new_formats_over_pty_reach_uwb_ranges(protocol, listener, processes, tmp_path):
    config_path = slot_config(tmp_path) if protocol != 'les' else PUMP_YAML
    config = load_pump_config(config_path)
    _, announced = start_any_emulator(processes, protocol, config_path)
    params = params_with_sources(tmp_path, config_path, announced, protocol)
    since = len(listener.ranges)
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(params)])
    assert listener.spin_until(lambda: len(listener.ranges) >= since + 8, 20), \
        driver.stderr.read() if driver.poll() is not None else 'no frames'
    check_ranges_against_truth(listener, config, since + 2, 6e-3)


def test_a_wifi_tag_that_connects_to_us_is_read_without_newlines(listener, processes):
    port = free_port()
    listener.diagnostics.clear()
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:=tcp-listen://127.0.0.1:{port}', '-p', 'protocol:=auto',
                        '-p', "tag:='01'"])
    message = ('{"links":[' + ','.join(f'{{"A":"{a}","R":"{2 + i}.5"}}' for i, a in
                                       enumerate(['1782', '1783', '1784', '1785', '1786',
                                                  '1787'])) + ']}').encode()
    deadline = time.monotonic() + 20
    while True:
        try:
            tag = socket.create_connection(('127.0.0.1', port), timeout=2)
            break
        except OSError:
            assert time.monotonic() < deadline and driver.poll() is None
            time.sleep(0.2)
    try:
        tag.sendall(b'GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n')
        since = len(listener.ranges)

        def sent_until(condition, timeout):
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                tag.sendall(message)
                if listener.spin_until(condition, 0.1):
                    return True
            return False

        assert sent_until(lambda: len(listener.ranges) >= since + 5, 20)
        frame = listener.ranges[-1]
        assert list(frame.position[:6]) == [2.5, 3.5, 4.5, 5.5, 6.5, 7.5]

        def values():
            return [{kv.key: kv.value for kv in status.values}
                    for status in listener.statuses(f'uwb_driver: tcp-listen://127.0.0.1:{port}')]

        assert sent_until(lambda: any(v['clients'] == '1' and v['preamble lines'] == '3'
                                      and v['protocol'] == 'json' for v in values()), 10)
        assert all('input backlog (bytes)' in v and 'newest line age (s)' in v
                   for v in values())
    finally:
        tag.close()
    assert driver.poll() is None


def connect_when_listening(port, driver, timeout=20):
    """Connect to the driver's listening port once it is bound."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return socket.create_connection(('127.0.0.1', port), timeout=2)
        except OSError:
            assert time.monotonic() < deadline and driver.poll() is None
            time.sleep(0.2)


def test_a_listening_port_is_never_locked_by_silent_or_stray_clients(listener, processes):
    """
    A stray arduino client talks first and seven more connect and say nothing.

    The real JSON tag, ninth, still gets in (the silent longest makes room) and is decoded
    as JSON (each client detects its own protocol).
    """
    port = free_port()
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:=tcp-listen://127.0.0.1:{port}', '-p', 'protocol:=auto',
                        '-p', "tag:='01'"])
    others = [connect_when_listening(port, driver)]
    try:
        others[0].sendall(b'from: 1782\t Range: 9.99 m\t RX power: -78.32 dBm\n' * 5)
        others += [socket.create_connection(('127.0.0.1', port), timeout=5) for _ in range(7)]
        name = f'uwb_driver: tcp-listen://127.0.0.1:{port}'
        assert listener.spin_until(lambda: any(
            kv.key == 'clients' and kv.value == '8' for status in listener.statuses(name)
            for kv in status.values), 30)
        message = ('{"links":[' + ','.join(f'{{"A":"{a}","R":"{2 + i}.5"}}' for i, a in
                                           enumerate(['1782', '1783', '1784', '1785', '1786',
                                                      '1787'])) + ']}').encode()
        with socket.create_connection(('127.0.0.1', port), timeout=5) as tag:
            since = len(listener.ranges)
            deadline = time.monotonic() + 30
            while len(listener.ranges) < since + 3 and time.monotonic() < deadline:
                tag.sendall(message)
                listener.spin_until(lambda: False, 0.1)
            assert len(listener.ranges) >= since + 3
            assert list(listener.ranges[-1].position[:6]) == [2.5, 3.5, 4.5, 5.5, 6.5, 7.5]
            values = lambda: {kv.key: kv.value  # noqa: E731
                              for kv in listener.statuses(name)[-1].values}
            assert listener.spin_until(
                lambda: int(values()['clients evicted by a newcomer']) >= 1
                and 'json' in values()['protocol'], 30), values()
    finally:
        for client in others:
            client.close()
    assert driver.poll() is None


def test_trek_anchor_ranges_reach_uwb_anchor_ranges(listener, processes, tmp_path):
    """``ma`` lines -> uwb_driver -> ``uwb/anchor_ranges``, beside unchanged ``uwb/ranges``."""
    from epp_ros.app import contract
    from epp_ros.nodes.messages import qos
    from sensor_msgs.msg import JointState
    received = []
    subscription = listener.create_subscription(JointState, contract.ANCHOR_RANGES.name,
                                                received.append, qos(contract.ANCHOR_RANGES))
    try:
        config_path = trek_config(tmp_path)
        config = load_pump_config(config_path)
        _, announced = start_emulator(processes, 'trek', ['--pty'], config_path)
        params = params_with_sources(tmp_path, config_path, announced, 'trek')
        since = len(listener.ranges)
        driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(params)])
        # One round a second after the start-up burst (which may pass before the driver opens
        # the port): wait for a few, however slow the machine.
        assert listener.spin_until(lambda: len(received) >= 3, 60), \
            driver.stderr.read() if driver.poll() is not None else 'no anchor ranges'

        def published():
            return max((int(kv.value) for status in listener.statuses('uwb_driver')
                        for kv in status.values if kv.key == 'anchor-anchor ranges published'),
                       default=0)

        assert listener.spin_until(lambda: published() >= 3, 30)
    finally:
        listener.destroy_subscription(subscription)
    model = config.model()
    distances = np.linalg.norm(model.anchors[:, None] - model.anchors[None], axis=-1)
    for message in received:
        # A0 prints A0-A1, A0-A2 and A1-A2, the measuring anchor first.
        assert list(message.name) == ['a0:a1', 'a0:a2', 'a1:a2']
        np.testing.assert_allclose(message.position,
                                   [distances[0, 1], distances[0, 2], distances[1, 2]],
                                   atol=5e-4 + 1e-9)
        assert message.header.frame_id == config.frame_id
        assert abs(to_seconds(message.header.stamp) - time.time()) < 30
        assert len(message.velocity) == len(message.effort) == 0
    stamps = [to_seconds(message.header.stamp) for message in received]
    assert stamps == sorted(stamps)
    check_ranges_against_truth(listener, config, since + 2, 1.5e-3)
