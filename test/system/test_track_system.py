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

"""posture_estimator with method track, over DDS: each tag's ranges at their own time."""
import time

from diagnostic_msgs.msg import DiagnosticStatus
from epp_ros.app.config import load_pump_config
from epp_ros.core import PostureEstimator
from epp_ros.nodes.messages import to_seconds, to_time
import numpy as np
import pytest
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_processes import poses_to_joints, PUMP_YAML, script
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.usefixtures('fresh_listener')
CONFIG = load_pump_config(PUMP_YAML)
MODEL = CONFIG.model()
PERIOD = 0.1            # s between frames (10 Hz)
SLOT = 0.02             # s between the tags' TDMA slots
FRAMES = 40
CHECKED = 10            # the last frames, once the tracker has learnt the rates
#: (slew, pitch1..pitch5) at the first stamp, rad, and their constant rates, rad/s
START = np.r_[0.3, np.radians([50.0, 20.0, 0.0, -20.0, -40.0])]
RATES = np.array([0.08, -0.05, 0.06, 0.07, -0.06, 0.09])


def boom_at(elapsed):
    """Joints (p, 3) of the turning boom ``elapsed`` seconds after the first stamp."""
    psi = START + elapsed * RATES
    return MODEL.forward_kinematics(psi[0], psi[1:])


def tdma_frames(start):
    """
    Build the frames of the turning boom, each tag's ranges exact at its own time.

    Tag k ranges ``(p - 1 - k) * SLOT`` seconds before the stamp (the last tag at it).

    Returns
    -------
    list of (builtin_interfaces/Time, ndarray (p, m), ndarray (p,), ndarray (p, 3))
        Stamp, ranges, each tag's age (s) and the true joints at the stamp.

    """
    p = MODEL.n_sections
    ages = (p - 1 - np.arange(p)) * SLOT
    frames = []
    for k in range(FRAMES):
        stamp = to_time(start + k * PERIOD)
        elapsed = to_seconds(stamp) - start
        ranges = np.array([MODEL.ranges(boom_at(elapsed - age))[tag]
                           for tag, age in enumerate(ages)])
        frames.append((stamp, ranges, ages, boom_at(elapsed)))
    return frames


def key(stamp):
    return stamp.sec, stamp.nanosec


def test_track_applies_each_tags_ranges_at_its_own_time(listener, processes):
    """
    Check that the node tracks a turning boom exactly from ranges of mixed instants.

    Every message's ``effort`` carries its ranges' ages (TDMA slots 20 ms apart), which the
    node passes to the tracker as each tag's measurement time: once the rates are learnt,
    the postures are the boom at their stamps. The same tracker told nothing of the ages
    (every range at the stamp) is several centimetres off on the same frames.
    """
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               '-p', 'method:=track'])
    keep_all = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          history=HistoryPolicy.KEEP_ALL)
    publisher = listener.create_publisher(JointState, 'uwb/ranges', keep_all)
    frames = tdma_frames(time.time())
    anchors = MODEL.n_anchors
    try:
        # The listener subscribes too: wait for the estimator as the second subscriber.
        assert listener.spin_until(lambda: publisher.get_subscription_count() >= 2, 10)
        for stamp, ranges, ages, _ in frames:
            message = JointState(name=CONFIG.link_names,
                                 position=[float(v) for v in ranges.ravel()],
                                 effort=[float(v) for v in np.repeat(ages, anchors)])
            message.header.stamp = stamp
            publisher.publish(message)
        report = {}

        def processed():
            """Find the estimator's first report that counts every frame received."""
            for status in listener.statuses('posture_estimator'):
                values = {kv.key: kv.value for kv in status.values}
                if values.get('frames received') == str(FRAMES):
                    report.update(values, level=status.level, message=status.message)
                    return True
            return False
        assert listener.spin_until(processed, 30), [
            (s.message, {kv.key: kv.value for kv in s.values if kv.key.startswith('frames')})
            for s in listener.statuses('posture_estimator')[-1:]]
        last = [key(stamp) for stamp, *_ in frames[-CHECKED:]]
        assert listener.spin_until(lambda: set(last) <= {
            key(m.header.stamp) for m in listener.postures}, 30), report
    finally:
        listener.destroy_publisher(publisher)
    # Every frame is published, each once, with its own stamp (the listener keeps the last
    # 10 postures it has not taken: under load it may miss earlier ones, never the last).
    assert report['method'] == 'track'
    assert report['frames published'] == str(FRAMES), report
    assert not [name for name in report if name.startswith('frames rejected')], report
    assert report['level'] != DiagnosticStatus.ERROR, report['message']
    postures = {key(m.header.stamp): poses_to_joints(m) for m in listener.postures}
    assert len(postures) == len(listener.postures)
    assert set(postures) <= {key(stamp) for stamp, *_ in frames}
    # The noise the estimator uses is reported: learnt from these exact ranges, below the
    # configured range_sigma (0.1 m).
    for name in ('range sigma [m]', 'range sigma per metre', 'NLOS fraction',
                 'NLOS mean excess [m]', 'outlier share', 'noise learned from links'):
        assert name in report, name
    assert 0.0 < float(report['range sigma [m]']) <= 0.1
    # The boom at each stamp, within 5 mm, once the tracker has learnt the rates.
    blind = PostureEstimator(MODEL, 'track')         # the same frames, ages ignored
    blind_errors = []
    for stamp, ranges, _, joints in frames:
        estimate = blind.update(ranges, stamp=to_seconds(stamp))
        blind_errors.append(np.linalg.norm(estimate - joints, axis=1).max())
    for (stamp, _, ages, joints), blind_error in zip(frames[-CHECKED:],
                                                     blind_errors[-CHECKED:]):
        error = np.linalg.norm(postures[key(stamp)] - joints, axis=1)
        assert error.max() < 0.005, (key(stamp), error)
        # Ignoring the ages costs centimetres: the test can fail.
        assert blind_error > 0.03
        # As measured, the tags' joints lag the boom at the stamp by centimetres too.
        elapsed = to_seconds(stamp) - to_seconds(frames[0][0])
        measured = np.array([boom_at(elapsed - age)[tag] for tag, age in enumerate(ages)])
        assert np.linalg.norm(measured - joints, axis=1).max() > 0.03
