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

"""emulator -> driver -> posture_estimator -> /arm_posture, as separate processes over DDS."""
import signal
import time

from diagnostic_msgs.msg import DiagnosticStatus
from epp_ros.app.config import load_pump_config
from epp_ros.core.estimation.metrics import frame_rmse
from epp_ros.nodes.messages import RANGES_QOS, to_seconds, to_time
import numpy as np
import pytest
import rclpy
from ros_processes import (Listener, poses_to_joints, PUMP_YAML, script, start_emulator,
                           truth_window, UNBIASED_ARGS)
from sensor_msgs.msg import JointState
import yaml

pytestmark = pytest.mark.usefixtures('fresh_listener')
CONFIG = load_pump_config(PUMP_YAML)
SIGMA = 0.05


def start_pump(processes, tmp_path, name='ttyUWB', namespace=None, extra=(), seed=0):
    """Emulator on a pty, driver and estimator; all under ``namespace`` if given."""
    link = str(tmp_path / name)
    remap = ['--ros-args', '-r', f'__ns:={namespace}'] if namespace else ['--ros-args']
    emulator, _ = start_emulator(
        processes, 'json', ['--pty', '--link', link],
        extra=['--sigma', str(SIGMA), '--seed', str(seed), *extra, *remap])
    driver = processes([script('uwb_driver'), *remap, '--params-file', str(PUMP_YAML),
                        '-p', f'port:={link}', '-p', 'protocol:=json'])
    estimator = processes([script('posture_estimator'), *remap, '--params-file',
                           str(PUMP_YAML), *UNBIASED_ARGS])
    return emulator, driver, estimator


#: Seconds: a frame is stamped when the driver reads it, which on a loaded machine can be
#: cycles after the emulator wrote it (a backlog read at start-up); its truth is among the
#: cycles this far before its stamp.
READ_LAG = 0.3


def matched_errors(listener):
    """
    Return the RMSE of each received posture against its truth.

    Its truth is the nearest of the truths published up to ``READ_LAG`` before its frame's
    stamp (the newest one when the driver kept up).
    """
    first, last = truth_window(listener)
    truth_stamps = np.array([to_seconds(m.header.stamp) for m in listener.truth])
    errors = []
    for posture in listener.postures:
        stamp = to_seconds(posture.header.stamp)
        if not first <= stamp <= last + 0.05:
            continue
        newest = np.searchsorted(truth_stamps, stamp) - 1
        oldest = max(np.searchsorted(truth_stamps, stamp - READ_LAG) - 1, 0)
        joints = poses_to_joints(posture)
        errors.append(min(frame_rmse(joints, poses_to_joints(listener.truth[index]))
                          for index in range(oldest, newest + 1)))
    return np.array(errors)


def test_markers_expire_so_a_refused_boom_leaves_the_screen():
    from epp_ros.nodes.messages import MARKER_LIFETIME, posture_markers
    joints = [[1.0, 0.0, 4.0], [2.0, 0.0, 5.0]]
    markers = posture_markers([0.0, 0.0, 3.5], joints, 12.5, 'pump_base').markers
    assert len(markers) == 3 and MARKER_LIFETIME == 1.0
    for marker in markers:
        assert (marker.lifetime.sec, marker.lifetime.nanosec) == (1, 0)
        assert (marker.header.stamp.sec, marker.header.stamp.nanosec) == (12, 500000000)


def test_postures_follow_the_truth(listener, processes, tmp_path):
    start_pump(processes, tmp_path)
    assert listener.spin_until(lambda: len(listener.postures) >= 30, 20)
    for posture in listener.postures:
        assert len(posture.poses) == 6 and posture.header.frame_id == CONFIG.frame_id
        values = [[p.position.x, p.position.y, p.position.z, p.orientation.x,
                   p.orientation.y, p.orientation.z, p.orientation.w] for p in posture.poses]
        assert np.all(np.isfinite(values))
        np.testing.assert_allclose(values[0][:3], CONFIG.base)
    errors = matched_errors(listener)
    assert errors.size >= 20
    # CEPP on this geometry: RMSE ~3.3 sigma (dev.py bench tracking); the bound leaves room.
    assert np.sqrt(np.mean(errors ** 2)) < 8 * SIGMA
    # Diagnostics: the paper's arm-length diagnostic and the solver's figures.
    assert listener.spin_until(lambda: listener.statuses('posture_estimator'), 3)
    status = listener.statuses('posture_estimator')[-1]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.OK, status.message
    assert float(values['section 5 abs error [m]']) < 1e-6
    assert values['method'] == 'cepp' and int(values['frames published']) >= 20
    for key in ('range residual RMS [m]', 'iterations', 'solve time [ms]', 'missing links'):
        assert key in values


def test_frames_missing_most_ranges_publish_no_nan(listener, processes, tmp_path):
    start_pump(processes, tmp_path, extra=['--drop', '0.85'])
    assert listener.spin_until(lambda: len(listener.ranges) >= 40, 20)
    listener.spin_until(lambda: False, 1.5)
    assert len(listener.postures) < len(listener.ranges)        # some frames were unsolvable
    for posture in listener.postures:
        values = [[p.position.x, p.position.y, p.position.z, p.orientation.w]
                  for p in posture.poses]
        assert np.all(np.isfinite(values))
    statuses = listener.statuses('posture_estimator')
    assert statuses
    counts = {kv.key: kv.value for kv in statuses[-1].values}
    assert int(counts['frames unsolved']) > 0


def test_out_of_order_and_duplicate_frames_are_ignored_and_counted(listener, processes):
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               *UNBIASED_ARGS])
    publisher = listener.create_publisher(JointState, 'uwb/ranges', RANGES_QOS)
    try:
        model = CONFIG.model()
        joints = model.forward_kinematics(0.3, np.radians([50.0, 20.0, 0.0, -20.0, -40.0]))
        ranges = [float(v) for v in model.ranges(joints).ravel()]

        def publish(stamp):
            message = JointState(name=CONFIG.link_names, position=ranges)
            message.header.stamp = to_time(stamp)
            publisher.publish(message)
        # The listener subscribes too: wait for the estimator as the second subscriber.
        assert listener.spin_until(lambda: publisher.get_subscription_count() >= 2, 60)
        # Our side matching is not the estimator's side matching: frames in time order until
        # one comes back as a posture, so that none of those below is lost to discovery.
        start = time.time() - 30.0
        for index in range(600):
            publish(start + 0.01 * index)
            if listener.spin_until(lambda: listener.postures, 0.1):
                break
        assert listener.spin_until(lambda: False, 1.0) or listener.postures
        listener.postures.clear()
        now = time.time()
        for stamp in (now, now + 0.1, now + 0.05, now + 0.1, now + 0.2):
            publish(stamp)
        assert listener.spin_until(lambda: len(listener.postures) >= 3, 60)
        listener.spin_until(lambda: False, 1.5)
        assert len(listener.postures) == 3
        np.testing.assert_allclose(poses_to_joints(listener.postures[-1]), joints, atol=1e-4)
        counts = {kv.key: kv.value
                  for kv in listener.statuses('posture_estimator')[-1].values}
        assert counts['frames out_of_order'] == '2'
    finally:
        listener.destroy_publisher(publisher)


def test_chain_fuses_boom_angles_and_tag_tag_ranges(listener, processes):
    """
    Without its ranges the tip is found from its inclinometer.

    A tag-tag range from the tip's hinge joint is always the section's length: it does not
    place the tip, and that frame is refused (the tip could be anywhere on its circle).
    """
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               '-p', 'method:=chain'])
    ranges_publisher = listener.create_publisher(JointState, 'uwb/ranges', RANGES_QOS)
    angles_publisher = listener.create_publisher(JointState, 'boom_angles', RANGES_QOS)
    try:
        model = CONFIG.model()
        slew, pitches = 0.3, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])
        joints = model.forward_kinematics(slew, pitches)
        ranges = model.ranges(joints)
        ranges[-1] = np.nan                                  # the tip's tag is blocked
        assert listener.spin_until(
            lambda: ranges_publisher.get_subscription_count() >= 2
            and angles_publisher.get_subscription_count() >= 1, 10)

        def publish_ranges(stamp, names=(), values=()):
            message = JointState(name=CONFIG.link_names + list(names),
                                 position=[float(v) for v in ranges.ravel()] + list(values))
            message.header.stamp = to_time(stamp)
            ranges_publisher.publish(message)

        def reported(key, value):
            """Wait until the estimator's diagnostics show ``key == value`` (1 Hz)."""
            return listener.spin_until(lambda: any(
                (key, value) in {(kv.key, kv.value) for kv in status.values}
                for status in listener.statuses('posture_estimator')), 10)

        now = time.time()
        publish_ranges(now)                                  # no angles: the tip is unseen
        assert reported('frames unsolved', '1')
        angles = JointState(name=['slew'] + [f'pitch{k}' for k in range(1, 6)],
                            position=[slew, *pitches])
        angles.header.stamp = to_time(now + 0.1)
        angles_publisher.publish(angles)
        assert reported('boom_angles messages', '1')
        publish_ranges(now + 0.1)                            # with fresh angles
        tip_link = np.linalg.norm(joints[-1] - joints[-2])
        publish_ranges(now + 1.0, ['joint4:joint5', 'joint5:joint4'], [tip_link, tip_link])
        assert listener.spin_until(lambda: len(listener.postures) >= 1, 10)
        assert reported('boom_angles frames_without_fresh_angles', '1')
        assert reported('frames unsolved', '2')
        assert len(listener.postures) == 1
        np.testing.assert_allclose(poses_to_joints(listener.postures[0]), joints, atol=1e-4)
        counts = {kv.key: kv.value
                  for kv in listener.statuses('posture_estimator')[-1].values}
        assert counts['frames published'] == '1' and counts['frames rejected unobservable'] == '1'
        assert counts['boom_angles frames_with_angles'] == '1'
    finally:
        listener.destroy_publisher(ranges_publisher)
        listener.destroy_publisher(angles_publisher)


def spin_all_until(nodes, condition, timeout):
    """Spin every node until ``condition()`` or ``timeout`` seconds; return whether met."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for node in nodes:
            rclpy.spin_once(node, timeout_sec=0.02)
        if condition():
            return True
    return False


def test_two_pumps_side_by_side_in_namespaces(processes, tmp_path):
    start_pump(processes, tmp_path, 'ttyPump1', '/pump1', seed=1)
    start_pump(processes, tmp_path, 'ttyPump2', '/pump2', seed=2)
    pumps = [Listener('listener1', '/pump1'), Listener('listener2', '/pump2')]
    try:
        # Six processes starting on a loaded machine: wait for the postures, generously.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and min(len(p.postures) for p in pumps) < 20:
            for pump in pumps:
                rclpy.spin_once(pump, timeout_sec=0.02)
        for pump in pumps:
            errors = matched_errors(pump)
            assert errors.size >= 10
            assert np.sqrt(np.mean(errors ** 2)) < 8 * SIGMA
        # Different seeds: the two booms are in different places.
        assert np.abs(poses_to_joints(pumps[0].postures[-1])
                      - poses_to_joints(pumps[1].postures[-1])).max() > 1.0
        # On the one /diagnostics each pump's statuses say which pump they are.
        for wanted in (('pump1/uwb_driver', 'pump2/uwb_driver'),
                       ('posture_estimator: /pump1', 'posture_estimator: /pump2')):
            assert spin_all_until(pumps, lambda: all(pumps[0].statuses(name)
                                                     for name in wanted), 60)
            ids = [pumps[0].statuses(name)[-1].hardware_id for name in wanted]
            assert ids[0] != ids[1] and ids[0].startswith('pump1/pump_base')
            assert ids[1].startswith('pump2/pump_base')
    finally:
        for pump in pumps:
            pump.destroy_node()


def hostile_stream(seconds=20.0, rate=10.0, seed=3):
    """
    Build a working cycle with a corrupted frame, a corrupted tip and absurd frames in it.

    Returns (stamps_ns, frames, bad indices), the stamps 0.1 s apart from now.
    """
    from epp_ros.core.simulation.simulate import RangeNoise, working_cycle
    model = CONFIG.model()
    trajectory = working_cycle(model, seconds, rate, rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    noise = RangeNoise(sigma=0.1, dropout=0.05)
    frames = [noise.apply(model.ranges(j), rng)[0] for j in trajectory.joints]
    bad = {50: 'all', 100: 'tip', 150: 'tenth', 151: 'zero'}
    for index, kind in bad.items():
        if kind == 'all':
            frames[index] = frames[index] * rng.uniform(0.0, 3.0, frames[index].shape)
        elif kind == 'tip':
            frames[index][-1] = frames[index][-1] * rng.uniform(0.0, 3.0, frames[index][-1].shape)
        else:
            frames[index] = np.full_like(frames[index], 0.1 if kind == 'tenth' else 0.0)
    for index in range(160, 172):          # 1.2 s unheard: the estimator starts cold
        frames[index] = np.full_like(frames[index], np.nan)
    start = time.time_ns()
    stamps = [start + int(round(1e9 * t)) for t in trajectory.times]
    stamps[180] = stamps[179]               # a repeated stamp: ignored by both
    return stamps, frames, sorted(bad)


def test_hostile_frames_are_not_published_and_eval_decides_the_same(listener, processes,
                                                                    tmp_path):
    """
    Check that the node and ``epp_bag eval`` publish and reject the same hostile frames.

    The node refuses corrupted and absurd frames and recovers; ``epp_bag eval`` on the
    same frames publishes exactly the same ones and rejects the rest for the same reasons,
    through a run of unsolved frames (a cold restart) and a repeated stamp.
    """
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from epp_ros.app import bags
    stamps, frames, bad = hostile_stream()
    # pump.yaml's settings, which epp_bag eval's estimator has by default.
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML)])
    keep_all = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          history=HistoryPolicy.KEEP_ALL)
    publisher = listener.create_publisher(JointState, 'uwb/ranges', keep_all)
    try:
        assert listener.spin_until(lambda: publisher.get_subscription_count() >= 2, 10)
        for stamp, ranges in zip(stamps, frames):
            message = JointState(name=CONFIG.link_names,
                                 position=[float(v) for v in ranges.ravel()])
            message.header.stamp = to_time(stamp * 1e-9)
            publisher.publish(message)
            listener.spin_until(lambda: False, 0.01)         # pace, and take postures
        counts = {}

        def processed():
            for status in listener.statuses('posture_estimator'):
                values = {kv.key: kv.value for kv in status.values}
                if values.get('frames received') == str(len(frames)):
                    counts.update(values)
                    return True
            return False
        assert listener.spin_until(processed, 60)
    finally:
        listener.destroy_publisher(publisher)
    received = {to_seconds(m.header.stamp) for m in listener.postures}
    for index in bad:
        assert round(stamps[index] * 1e-9, 6) not in {round(s, 6) for s in received}
    for posture in listener.postures:
        values = [[p.position.x, p.position.y, p.position.z] for p in posture.poses]
        assert np.all(np.isfinite(values)) and min(v[2] for v in values) >= -0.5
    # Offline, the same frames: the same decisions, counted the same way.
    bag = tmp_path / 'hostile'
    bags.write_frames(bag, CONFIG, zip(stamps, frames))
    result = bags.evaluate(bag, CONFIG, 'cepp')
    assert counts['frames published'] == str(result['solved'])
    assert result['rejected']['insufficient_data'] >= 12 and int(counts['frames cold_restarts'])
    for reason, count in result['rejected'].items():
        assert counts[f'frames rejected {reason}'] == str(count)
    assert result['ignored'] == {'out_of_order': 1} and counts['frames out_of_order'] == '1'
    published = {round(s * 1e-9, 6) for s in result['published_stamps_ns']}
    assert {round(s, 6) for s in received} <= published
    for index in bad:                  # refused, and a good frame published within 2 s
        assert round(stamps[index] * 1e-9, 6) not in published
        later = [round(s * 1e-9, 6) in published for s in stamps[index + 1:index + 21]]
        assert any(later)


class StillBoom:
    """Publishes one posture's ranges on ``uwb/ranges``, frames 0.1 s apart, as a driver."""

    JOINTS = CONFIG.model().forward_kinematics(0.3, np.radians([50.0, 20.0, 0.0, -20.0,
                                                                -40.0]))

    def __init__(self, listener, profile=RANGES_QOS):
        self.publisher = listener.create_publisher(JointState, 'uwb/ranges', profile)
        self.ranges = [float(v) for v in CONFIG.model().ranges(self.JOINTS).ravel()]
        self.sent = time.time()

    def publish(self):
        """Publish the next frame; False, so that it can stand first in a wait's condition."""
        self.sent += 0.1
        message = JointState(name=CONFIG.link_names, position=self.ranges)
        message.header.stamp = to_time(self.sent)
        self.publisher.publish(message)
        return False


def set_parameters(node, target, **values):
    """Call ``target``'s SetParameters service; a list of (successful, reason)."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    client = node.create_client(SetParameters, f'{target}/set_parameters')
    try:
        assert client.wait_for_service(timeout_sec=20)
        request = SetParameters.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
        future = client.call_async(request)
        assert node.spin_until(future.done, 20)
        return [(r.successful, r.reason) for r in future.result().results]
    finally:
        node.destroy_client(client)


def test_parameters_are_applied_live_or_refused(listener, processes):
    """
    Check that parameters are applied live or refused over the real SetParameters service.

    Valid changes apply from the next frame (a new method starting cold), invalid ones are
    refused with the reason, read-only ones too.
    """
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               *UNBIASED_ARGS])
    boom = StillBoom(listener)
    publisher, publish, joints = boom.publisher, boom.publish, StillBoom.JOINTS

    def reported(key):
        """Get the newest value of ``key`` in the estimator's diagnostics, after a new report."""
        seen = len(listener.statuses('posture_estimator'))
        assert listener.spin_until(
            lambda: len(listener.statuses('posture_estimator')) > seen + 1, 10)
        values = {kv.key: kv.value for kv in listener.statuses('posture_estimator')[-1].values}
        return values.get(key)
    try:
        assert listener.spin_until(lambda: publisher.get_subscription_count() >= 2, 10)
        publish()
        assert listener.spin_until(lambda: len(listener.postures) >= 1, 10)
        before = float(reported('predicted RMSE [m]'))
        refused = {'method': 'nonsense', 'range_sigma': -1.0, 'reset_after_failures': 0,
                   'angle_max_age': 0.0, 'arm_lengths': [1.0] * 5, 'slew_name': 'turret'}
        for name, value in refused.items():
            [(successful, reason)] = set_parameters(listener, '/posture_estimator',
                                                    **{name: value})
            assert not successful and reason, name
        assert set_parameters(listener, '/posture_estimator', range_sigma=0.3) == [(True, '')]
        publish()
        assert listener.spin_until(lambda: len(listener.postures) >= 2, 10)
        after = float(reported('predicted RMSE [m]'))
        assert after == pytest.approx(3 * before, rel=1e-3)      # the bound scales with sigma
        assert set_parameters(listener, '/posture_estimator', method='chain') == [(True, '')]
        publish()
        assert listener.spin_until(lambda: len(listener.postures) >= 3, 10)
        assert reported('method') == 'chain' and reported('frames method_changes') == '1'
        np.testing.assert_allclose(poses_to_joints(listener.postures[-1]), joints, atol=1e-4)
    finally:
        listener.destroy_publisher(publisher)


def test_a_calibrated_pump_weighs_each_link_by_its_own(listener, processes, tmp_path):
    """A pump.yaml with link_offset_std: each link's own bias, link_bias_std not settable."""
    from epp_ros.app.health import joint_stds
    from epp_ros.core import PostureEstimator
    document = yaml.safe_load(PUMP_YAML.read_text())
    stds = np.full(30, 0.01)
    stds[24:] = 0.3                                 # the tip's links known to 0.3 m
    document['/**']['ros__parameters']['link_offset_std'] = stds.tolist()
    calibrated = tmp_path / 'pump.yaml'
    calibrated.write_text(yaml.safe_dump(document))
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(calibrated),
               *UNBIASED_ARGS, '-p', 'learn_noise:=false'])
    # What the library predicts for the tip told so, and told one number for every link.
    told = {'learn_noise': False, 'common_bias_std': 0.0, 'bias_slope_std': 0.0, 'anchor_std': 0.0}
    tip = {}
    for name, link_bias_std in (('per link', stds.reshape(5, 6)), ('none', 0.0)):
        estimator = PostureEstimator(CONFIG.model(), 'cepp', link_bias_std=link_bias_std,
                                     **told)
        for _ in range(3):
            estimator.update(CONFIG.model().ranges(StillBoom.JOINTS))
        tip[name] = estimator.last_diagnostics['joint_std'][-1]
    assert tip['per link'] > 1.1 * tip['none']
    boom = StillBoom(listener)
    publisher, publish = boom.publisher, boom.publish

    def reported_tip_std():
        statuses = listener.statuses('posture_estimator')
        values = {kv.key: kv.value for kv in statuses[-1].values} if statuses else {}
        return joint_stds(values, 5)[-1]
    try:
        assert listener.spin_until(lambda: publisher.get_subscription_count() >= 2, 10)
        assert listener.spin_until(lambda: publish() or len(listener.postures) >= 3, 20)
        np.testing.assert_allclose(poses_to_joints(listener.postures[-1]), StillBoom.JOINTS,
                                   atol=1e-3)
        assert listener.spin_until(lambda: np.isfinite(reported_tip_std()), 10)
        assert reported_tip_std() == pytest.approx(tip['per link'], rel=1e-2)
        [(successful, reason)] = set_parameters(listener, '/posture_estimator',
                                                link_bias_std=0.2)
        assert not successful and 'link_offset_std' in reason
    finally:
        listener.destroy_publisher(publisher)


def test_a_best_effort_publisher_reaches_an_estimator_told_sensor_data(listener, processes):
    """``ranges_qos: sensor_data`` (read-only); silence then reads as ERROR, never STALE."""
    from rclpy.qos import qos_profile_sensor_data
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               '-p', 'ranges_qos:=sensor_data', *UNBIASED_ARGS])
    boom = StillBoom(listener, qos_profile_sensor_data)
    try:
        assert listener.spin_until(lambda: boom.publish() or len(listener.postures) >= 3, 60)
        np.testing.assert_allclose(poses_to_joints(listener.postures[-1]), StillBoom.JOINTS,
                                   atol=1e-4)
    finally:
        listener.destroy_publisher(boom.publisher)
    assert set_parameters(listener, '/posture_estimator', ranges_qos='reliable')[0][0] is False
    silent = lambda: any(s.level == DiagnosticStatus.ERROR  # noqa: E731
                         and s.message.startswith('no uwb/ranges for')
                         for s in listener.statuses('posture_estimator'))
    assert listener.spin_until(silent, 30)
    assert not any(s.level == DiagnosticStatus.STALE
                   for s in listener.statuses('posture_estimator'))


def latest_values(listener, prefix):
    """Return the newest status values of a node's diagnostics, as a dict (empty: none)."""
    statuses = listener.statuses(prefix)
    return {kv.key: kv.value for kv in statuses[-1].values} if statuses else {}


def test_frames_lost_while_the_estimator_lags_are_counted_exactly(
        listener, processes, tmp_path):
    """
    Stop the estimator while the driver publishes 300 frames at 50 Hz, then let it go on.

    The driver's writer keeps the newest 100 frames for a reader that is behind: the rest
    are lost on the way, and the estimator counts them from the frames' numbers. Every
    frame the driver published is one the estimator received, lost or never listened for.
    """
    emulator, driver, estimator = start_pump(processes, tmp_path, extra=['--rate', '50'])
    assert listener.spin_until(lambda: len(listener.postures) >= 5, 60), \
        estimator.stderr.read() if estimator.poll() is not None else 'no postures'
    estimator.send_signal(signal.SIGSTOP)
    try:
        seen = len(listener.ranges)
        assert listener.spin_until(lambda: len(listener.ranges) >= seen + 300, 120)
    finally:
        estimator.send_signal(signal.SIGCONT)
    emulator.send_signal(signal.SIGINT)
    emulator.wait(30)
    stopped = time.monotonic()

    def balanced():
        frames, counts = latest_values(listener, 'uwb_driver'), latest_values(
            listener, 'posture_estimator')
        if time.monotonic() < stopped + 3 or not frames or not counts:
            return False            # reports made after the last frame
        heard = sum(int(counts[f'frames {key}']) for key in ('received', 'lost',
                                                             'before_first'))
        return heard == int(frames['frames'])
    assert listener.spin_until(balanced, 120), (latest_values(listener, 'uwb_driver'),
                                                latest_values(listener, 'posture_estimator'))
    counts = latest_values(listener, 'posture_estimator')
    assert int(counts['frames lost']) > 0, counts       # the lag did lose frames
    assert int(counts['frames sender_restarts']) == 0
