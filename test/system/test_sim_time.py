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
use_sim_time: the nodes stamp with simulated time from /clock (a bag's, or a test's own).

The simulated time starts at 1000 s (1970), so that no wall-clock stamp can pass for it.
"""
import subprocess
import time

from epp_ros.nodes.messages import to_seconds, to_time
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_processes import PUMP_YAML, script, start_emulator
from rosgraph_msgs.msg import Clock

pytestmark = pytest.mark.usefixtures('fresh_listener')
SIM_START = 1000.0      # s since the epoch: plainly simulated
BAG_SECONDS = 8.0


def simulated(stamp, end=SIM_START + 3600.0):
    return SIM_START <= to_seconds(stamp) <= end


class SimClock:
    """Publishes /clock from SIM_START on, at the pace of the wall clock, when ticked."""

    def __init__(self, listener):
        self.publisher = listener.create_publisher(
            Clock, '/clock', QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.started = time.monotonic()

    def tick(self):
        self.publisher.publish(Clock(clock=to_time(SIM_START + time.monotonic()
                                                   - self.started)))
        return False


@pytest.fixture
def sim_bag(tmp_path):
    bag = tmp_path / 'sim'
    result = subprocess.run([script('epp_bag'), 'synth', str(bag), '--duration',
                             str(BAG_SECONDS), '--sigma', '0.05', '--start', str(SIM_START)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return bag


def play_into_sim_time_estimator(listener, processes, bag):
    """Replay ``bag`` with --clock into an estimator on simulated time; return the player."""
    estimator = processes([script('posture_estimator'), '--ros-args', '--params-file',
                           str(PUMP_YAML), '-p', 'use_sim_time:=true'])
    # The player waits (up to 10 s) for the estimator's ranges and /clock subscriptions.
    player = processes([script('epp_bag'), 'play', str(bag), '--clock', '--topics',
                        '/uwb/ranges', '--subscribers', '1'])
    assert listener.spin_until(lambda: len(listener.postures) >= 20, 60), \
        estimator.stderr.read() if estimator.poll() is not None else 'no postures'
    assert listener.spin_until(lambda: player.poll() is not None, 60)
    assert player.returncode == 0, player.stderr.read()
    return estimator


def test_replay_with_clock_gives_postures_in_the_bags_time(listener, processes, sim_bag):
    play_into_sim_time_estimator(listener, processes, sim_bag)
    end = SIM_START + BAG_SECONDS
    assert all(simulated(p.header.stamp, end) for p in listener.postures), \
        [to_seconds(p.header.stamp) for p in listener.postures if not simulated(p.header.stamp)]
    # With use_sim_time the estimator's 1 Hz timer runs on the bag's clock, so its
    # diagnostics come while the bag plays (and stop with its clock).
    assert listener.statuses('posture_estimator')


def test_replay_with_clock_gives_diagnostics_in_the_bags_time(listener, processes, sim_bag):
    """Needs estimator.py to stamp /diagnostics with its node clock (issue #16, part 3)."""
    play_into_sim_time_estimator(listener, processes, sim_bag)
    listener.spin_until(lambda: False, 1.0)
    stamps = [a.header.stamp for a in listener.diagnostics
              if any(s.name.startswith('posture_estimator') for s in a.status)]
    assert stamps
    assert all(simulated(stamp, SIM_START + BAG_SECONDS + 1.0) for stamp in stamps), \
        [to_seconds(stamp) for stamp in stamps]


def test_emulator_and_driver_stamp_with_sim_time(listener, processes, tmp_path):
    clock = SimClock(listener)
    link = str(tmp_path / 'ttyUWB')
    sim = ['--ros-args', '-p', 'use_sim_time:=true']
    start_emulator(processes, 'json', ['--pty', '--link', link], extra=sim)
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:={link}', '-p', 'protocol:=json',
                        '-p', 'use_sim_time:=true'])
    enough = lambda: len(listener.ranges) >= 10 and len(listener.truth) >= 10  # noqa: E731
    assert listener.spin_until(lambda: clock.tick() or enough(), 60), \
        driver.stderr.read() if driver.poll() is not None else 'no frames'
    ranges = [m.header.stamp for m in listener.ranges]
    assert all(simulated(stamp) for stamp in ranges), [to_seconds(s) for s in ranges]
    truth = [m.header.stamp for m in listener.truth[3:]]
    assert all(simulated(stamp) for stamp in truth), [to_seconds(s) for s in truth]
    driver_statuses = [a for a in listener.diagnostics
                       if any(s.name.startswith('uwb_driver') for s in a.status)]
    assert listener.spin_until(lambda: clock.tick() or any(
        simulated(a.header.stamp) for a in listener.diagnostics
        if any(s.name.startswith('uwb_driver') for s in a.status)), 30), driver_statuses


def test_driver_stamps_nothing_before_the_first_clock(listener, processes, tmp_path):
    """Lines read before any /clock are counted as dropped, never stamped 0 + 1 us, ..."""
    link = str(tmp_path / 'ttyUWB')
    start_emulator(processes, 'json', ['--pty', '--link', link])      # on wall time
    driver = processes([script('uwb_driver'), '--ros-args', '--params-file', str(PUMP_YAML),
                        '-p', f'port:={link}', '-p', 'protocol:=json',
                        '-p', 'use_sim_time:=true'])
    assert listener.spin_until(lambda: listener.count_publishers('uwb/ranges') >= 1, 60), \
        driver.stderr.read() if driver.poll() is not None else 'no driver'
    seen = len(listener.truth)          # the emulator's cycles: lines the driver reads
    assert listener.spin_until(lambda: len(listener.truth) >= seen + 20, 60)
    clock = SimClock(listener)
    assert listener.spin_until(lambda: clock.tick() or len(listener.ranges) >= 10, 60)

    def dropped():
        statuses = [s for a in listener.diagnostics for s in a.status
                    if s.name.startswith('uwb_driver')]
        values = {kv.key: kv.value for kv in statuses[-1].values} if statuses else {}
        return int(values.get('dropped before /clock', 0))
    stamps = [m.header.stamp for m in listener.ranges]
    assert all(simulated(stamp) for stamp in stamps), [to_seconds(s) for s in stamps]
    assert listener.spin_until(lambda: clock.tick() or dropped() > 0, 30)


@pytest.mark.parametrize('clock_type', ['rosgraph_msgs/msg/Clock', 'std_msgs/msg/String'])
def test_play_with_clock_puts_one_clock_on_clock(listener, processes, sim_bag, tmp_path,
                                                 clock_type):
    """A bag's own /clock (here 5000 s, or not even a Clock) is not played beside ours."""
    from epp_ros.app import bags
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    message = (bags.TYPESTORE.types[clock_type](clock=bags.TYPESTORE.types[
        'builtin_interfaces/msg/Time'](sec=5000, nanosec=0))
               if clock_type.endswith('Clock') else
               bags.TYPESTORE.types[clock_type](data='tick'))
    own = [('/clock', clock_type, int((SIM_START + k * 0.5) * 1e9), bags._serialize(message),
            None) for k in range(16)]
    bag = tmp_path / 'with_clock'
    bags.write_raw(bag, bags.read_all(sim_bag, topics=['/uwb/ranges'])[0] + own)
    heard = []
    subscription = listener.create_subscription(
        Clock, '/clock', heard.append,
        QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    try:
        player = processes([script('epp_bag'), 'play', str(bag), '--clock', '--subscribers',
                            '1'])
        assert listener.spin_until(lambda: player.poll() is not None, 120)
        assert player.returncode == 0, player.stderr.read()
        said = player.stderr.read()
        assert said.count('\n') == 1 and "the bag's own /clock (16 messages" in said, said
        assert heard and all(simulated(m.clock, SIM_START + BAG_SECONDS) for m in heard)
    finally:
        listener.destroy_subscription(subscription)
