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

"""Measuring a running posture_estimator from outside, over DDS (used by the benchmarks)."""
import os
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from epp_ros.app import contract
from epp_ros.app.config import default_config_path, load_pump_config
from epp_ros.nodes.messages import POSTURE_QOS, RANGES_INPUT_QOS, RANGES_QOS, to_time
from geometry_msgs.msg import PoseArray
import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

__all__ = ['measure_latency', 'parameter_response', 'pinned_latency', 'sustained_rate',
           'replay_rate']


class _Feeder(Node):
    """Publishes range frames and times the postures that answer them."""

    def __init__(self, names):
        super().__init__('epp_bench_feeder')
        self.names = names
        self.publisher = self.create_publisher(JointState, contract.RANGES.name, RANGES_QOS)
        self.sent, self.answered = {}, {}
        self.create_subscription(PoseArray, contract.POSTURE.name, self._on_posture,
                                 POSTURE_QOS)

    def _on_posture(self, message):
        key = (message.header.stamp.sec, message.header.stamp.nanosec)
        if key in self.sent:
            self.answered[key] = time.perf_counter() - self.sent[key]

    def publish(self, ranges, stamp):
        message = JointState(name=self.names, position=[float(v) for v in ranges.ravel()])
        message.header.stamp = to_time(stamp)
        key = (message.header.stamp.sec, message.header.stamp.nanosec)
        self.sent[key] = time.perf_counter()
        self.publisher.publish(message)


def _with_estimator(method, work, core=None):
    """
    Run ``work(feeder)`` against a fresh posture_estimator process.

    The process runs on a domain of its own, set in this process's environment while
    ``work`` runs (the estimator and any player ``work`` starts inherit it). With a
    ``core``, the estimator runs on that CPU alone (before its DDS threads start).
    """
    config = default_config_path()
    names = load_pump_config(config).link_names
    args = [sys.executable, '-m', 'epp_ros.nodes.estimator', '--ros-args', '--params-file',
            str(config), '-p', f'method:={method}', '-p', 'publish_markers:=false',
            '--log-level', 'warn']
    saved = os.environ.get('ROS_DOMAIN_ID')
    os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 100)
    estimator = subprocess.Popen(args)
    if core is not None:
        os.sched_setaffinity(estimator.pid, {core})
    rclpy.init()
    feeder = _Feeder(names)
    try:
        deadline = time.monotonic() + 20
        while feeder.publisher.get_subscription_count() < 1:
            rclpy.spin_once(feeder, timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise RuntimeError('posture_estimator did not come up')
        return work(feeder)
    finally:
        feeder.destroy_node()
        rclpy.shutdown()
        estimator.send_signal(signal.SIGINT)
        estimator.wait(10)
        if saved is None:
            os.environ.pop('ROS_DOMAIN_ID')
        else:
            os.environ['ROS_DOMAIN_ID'] = saved


#: Frames are 10 Hz samples of a motion; a frame stamped t shows the boom at t (held
#: between samples), so that faster feeds do not make the boom jump (which the estimator
#: would rightly refuse).
FRAME_RATE = 10.0
_EPOCH = time.time()


def _feed(feeder, frames, rate, count, each_frame=None):
    """
    Publish ``count`` frames at ``rate``, then wait for the answers; return how many had none.

    A frame the node refuses publishes no posture: it counts here as a lost one does.

    ``each_frame(i)``, if given, is called after frame ``i`` is published.
    """
    start = time.perf_counter()
    base = time.time()
    for i in range(count):
        target = start + i / rate
        while time.perf_counter() < target:
            rclpy.spin_once(feeder, timeout_sec=max(0.0, min(0.001, target -
                                                             time.perf_counter())))
        stamp = base + i / rate
        feeder.publish(frames[int((stamp - _EPOCH) * FRAME_RATE) % len(frames)], stamp)
        if each_frame is not None:
            each_frame(i)
    deadline = time.perf_counter() + 3.0
    while len(feeder.answered) < len(feeder.sent) and time.perf_counter() < deadline:
        rclpy.spin_once(feeder, timeout_sec=0.01)
    return len(feeder.sent) - len(feeder.answered)


def measure_latency(method, frames, rate, seconds):
    """Latencies (s) of the answered frames at ``rate`` Hz, and how many were not answered."""
    def work(feeder):
        _feed(feeder, frames, 10.0, 10)                  # warm start and DDS settle
        feeder.sent.clear()
        feeder.answered.clear()
        lost = _feed(feeder, frames, rate, int(rate * seconds))
        return np.array(list(feeder.answered.values())), lost
    return _with_estimator(method, work)


def _frame_counts(array):
    """Return the estimator's frame counts of a DiagnosticArray ({} when it has none)."""
    return {value.key[len('frames '):]: int(value.value) for status in array.status
            if status.name.startswith('posture_estimator') for value in status.values
            if value.key.startswith('frames ') and value.value.isdigit()}


def pinned_latency(method, frames, rate, seconds, core=0):
    """
    :func:`measure_latency` with the estimator on one core that a busy process shares.

    A controller-class budget: the node gets half of one core (the scheduler shares it
    with a process that never sleeps), the feeder runs on the other cores. Returns the
    latencies (s), the frames not answered, and the node's own frame counts at the end
    (``/diagnostics``: ``received``, ``published``, ``unsolved``, ...; warm-up included).
    """
    others = os.sched_getaffinity(0) - {core}
    if not others:
        raise RuntimeError('pinned_latency needs two cores: one for the node, one to feed it')
    saved = os.sched_getaffinity(0)
    load = subprocess.Popen([sys.executable, '-c', 'while True: pass'])
    try:
        os.sched_setaffinity(load.pid, {core})
        os.sched_setaffinity(0, others)

        def work(feeder):
            counts = {}
            feeder.create_subscription(DiagnosticArray, contract.DIAGNOSTICS.name,
                                       lambda array: counts.update(_frame_counts(array)),
                                       contract.DIAGNOSTICS.depth)
            _feed(feeder, frames, 10.0, 10)              # warm start and DDS settle
            feeder.sent.clear()
            feeder.answered.clear()
            lost = _feed(feeder, frames, rate, int(rate * seconds))
            counts.clear()
            deadline = time.perf_counter() + 5.0        # the node reports once a second
            while not counts and time.perf_counter() < deadline:
                rclpy.spin_once(feeder, timeout_sec=0.05)
            return np.array(list(feeder.answered.values())), lost, counts
        return _with_estimator(method, work, core)
    finally:
        load.kill()
        load.wait()
        os.sched_setaffinity(0, saved)


#: Valid live changes sent by :func:`parameter_response`: (name, values it cycles through).
LIVE_CHANGES = (('range_sigma', (0.05, 0.2, 0.1)), ('lowest_joint', (-1.0, -0.5)),
                ('nlos_fraction', (0.2, 0.1)), ('max_angular_rate', (0.2, 0.35)))


def _double(name, value):
    return Parameter(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                     double_value=float(value)))


def parameter_response(method, frames, seconds, every=5):
    """
    Response times (s) of ``set_parameters`` calls made while frames flow at 10 Hz.

    One call every ``every`` frames, cycling through :data:`LIVE_CHANGES` (valid values;
    ``bench speed`` has the cost of refused frames). A told ``range_sigma`` or
    ``nlos_fraction`` starts the noise's learning over, and for a few frames a joint may be
    ambiguous at the told noise: those frames are refused, and counted unanswered. Returns
    the response times, the frames' latencies, frames unanswered (refused or lost) and
    calls unanswered or refused.
    """
    def work(feeder):
        client = feeder.create_client(SetParameters, '/posture_estimator/set_parameters')
        if not client.wait_for_service(timeout_sec=20.0):
            raise RuntimeError('posture_estimator/set_parameters did not come up')
        _feed(feeder, frames, 10.0, 10)
        feeder.sent.clear()
        feeder.answered.clear()
        responses, pending = [], []

        def change(i):
            if i % every:
                return
            name, values = LIVE_CHANGES[(i // every) % len(LIVE_CHANGES)]
            value = values[(i // every // len(LIVE_CHANGES)) % len(values)]
            sent = time.perf_counter()
            future = client.call_async(SetParameters.Request(parameters=[_double(name, value)]))
            future.add_done_callback(lambda _: responses.append(time.perf_counter() - sent))
            pending.append(future)
        lost = _feed(feeder, frames, 10.0, int(10.0 * seconds), change)
        deadline = time.perf_counter() + 30.0
        while not all(f.done() for f in pending) and time.perf_counter() < deadline:
            rclpy.spin_once(feeder, timeout_sec=0.01)
        refused = sum(not f.result().results[0].successful for f in pending if f.done())
        return (np.array(responses), np.array(list(feeder.answered.values())), lost,
                sum(not f.done() for f in pending) + refused)
    return _with_estimator(method, work)


def sustained_rate(method, frames,
                   rates=(50, 100, 150, 200, 300, 500, 700, 1000, 1500, 2000), seconds=2.0,
                   max_latency=0.1):
    """
    Return the highest of ``rates`` (frames/s) at which the node keeps up for ``seconds``.

    Keeping up is every frame answered, none later than ``max_latency`` s (the input queue
    keeps everything, so a node that is too slow loses nothing but falls ever further
    behind).
    """
    def work(feeder):
        _feed(feeder, frames, 10.0, 10)
        best = 0
        for rate in rates:
            feeder.sent.clear()
            feeder.answered.clear()
            lost = _feed(feeder, frames, rate, int(rate * seconds))
            if lost > 0 or max(feeder.answered.values()) > max_latency:
                break
            best = rate
            time.sleep(0.5)
        return best
    return _with_estimator(method, work)


def replay_rate(method, bag, frames):
    """Frames/s and lost frames when ``epp_bag play --fast`` feeds the estimator node."""
    def work(feeder):
        received = []
        feeder.create_subscription(PoseArray, contract.POSTURE.name,  # keep all: measure
                                   lambda message: received.append(time.perf_counter()),
                                   RANGES_INPUT_QOS)
        player = subprocess.Popen([sys.executable, '-m', 'epp_ros.cli.bag', 'play',
                                   str(bag), '--fast', '--topics', contract.RANGES.absolute],
                                  stdout=subprocess.DEVNULL)
        start = time.perf_counter()
        deadline = start + 60.0
        while len(received) < frames and time.perf_counter() < deadline:
            rclpy.spin_once(feeder, timeout_sec=0.01)
        player.wait(30)
        for _ in range(50):                     # late answers
            rclpy.spin_once(feeder, timeout_sec=0.01)
        elapsed = (received[-1] - received[0]) if len(received) > 1 else float('nan')
        return (len(received) - 1) / elapsed, frames - len(received)
    return _with_estimator(method, work)
