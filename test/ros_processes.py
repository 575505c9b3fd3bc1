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

"""Helpers of the multi-process tests: installed executables, a listening node, emulators."""
from dataclasses import replace
from pathlib import Path
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from epp_ros.app import contract
from epp_ros.app.config import load_pump_config
from epp_ros.nodes.messages import qos, to_seconds
from geometry_msgs.msg import PoseArray
import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
import yaml

ROOT = Path(__file__).resolve().parents[1]
PUMP_YAML = ROOT / 'config' / 'pump.yaml'
#: Node arguments telling the estimator that the emulated pump's ranges are unbiased and its
#: outriggers where configured (pump.yaml allows for the biases of real links and for
#: outriggers set up again, which widen its predicted RMSE).
UNBIASED_ARGS = ('-p', 'link_bias_std:=0.0', '-p', 'common_bias_std:=0.0', '-p',
                 'bias_slope_std:=0.0', '-p', 'anchor_std:=0.0')
BIN = Path(sys.executable).parent


def _executables():
    """
    Where this package's executables are.

    Where ``ros2 run`` finds them when a colcon install is on the ament index (``colcon
    test``), else beside this Python (``python3 dev.py test``: the venv's console scripts).
    """
    try:
        from ament_index_python.packages import get_package_prefix, PackageNotFoundError
        return Path(get_package_prefix('epp_ros')) / 'lib' / 'epp_ros'
    except (ImportError, PackageNotFoundError):
        return BIN


EXECUTABLES = _executables()


def script(name):
    """Path of an installed executable of this package."""
    path = EXECUTABLES / name
    if not path.exists():
        pytest.fail(f'{name} is not installed in {EXECUTABLES}: run `python3 dev.py test` '
                    'or `colcon build` first')
    return str(path)


def everything(topic):
    """Return ``topic``'s QoS profile keeping all messages (the reader's history only)."""
    return qos(replace(topic, depth=None))


class Listener(Node):
    """Collects what a pump's nodes publish (topics relative to ``namespace``)."""

    def __init__(self, name='test_listener', namespace=''):
        super().__init__(name, namespace=namespace)
        self.ranges, self.truth, self.diagnostics, self.postures = [], [], [], []
        # The contract's profiles, but every message kept until taken: a test process
        # stalled on a loaded machine must not lose what a fast node published meanwhile.
        self.create_subscription(JointState, 'uwb/ranges', self.ranges.append,
                                 everything(contract.RANGES))
        self.create_subscription(PoseArray, 'arm_posture/ground_truth', self.truth.append,
                                 everything(contract.TRUTH))
        self.create_subscription(PoseArray, 'arm_posture', self.postures.append,
                                 everything(contract.POSTURE))
        self.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)

    def spin_until(self, condition, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            rclpy.spin_once(self, timeout_sec=0.05)
            if condition():
                return True
        return False

    def clear(self):
        self.spin_until(lambda: False, 0.2)
        for received in (self.ranges, self.truth, self.diagnostics, self.postures):
            received.clear()

    def statuses(self, prefix):
        return [status for array in self.diagnostics for status in array.status
                if status.name.startswith(prefix)]


class Processes:
    """Starts processes and stops them all (SIGINT, then SIGKILL) at the end of a test."""

    def __init__(self):
        self.started = []

    def __call__(self, args, env=None):
        process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, env=env)
        self.started.append(process)
        return process

    def stop_all(self):
        for process in self.started:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in self.started:
            try:
                process.wait(5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            process.stdout.close()
            process.stderr.close()


def start_emulator(start, protocol, where, config=PUMP_YAML, extra=()):
    """Start uwb_emulator with truth and no noise; return it and its announced channels."""
    emulator = start([script('uwb_emulator'), '--protocol', protocol, *where, '--truth',
                      '--sigma', '0', '--rate', '10', '--config', str(config), *extra])
    announced = []
    while len(announced) < channels(protocol, config):
        line = emulator.stdout.readline()
        if not line.startswith(('PTY', 'TCP')):
            break
        announced.append(line.split())
    assert announced, emulator.stderr.read()
    return emulator, announced


def channels(protocol, config):
    return 1 if protocol in ('json', 'trek') else len(load_pump_config(config).tag_ids)


def params_with_sources(tmp_path, config, announced, protocol, name='params.yaml'):
    """Write a parameters file: the pump description with the emulator's ports as sources."""
    document = yaml.safe_load(Path(config).read_text())
    shared = document['/**']['ros__parameters']
    shared['source_ports'] = [a[1] for a in announced]
    shared['source_protocols'] = [protocol] * len(announced)
    shared['source_tags'] = [a[2] if len(a) > 2 else '' for a in announced]
    path = tmp_path / name
    path.write_text(yaml.safe_dump(document))
    return path


def poses_to_joints(message):
    """(p, 3) joints of a PoseArray that holds the base first."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in message.poses[1:]])


def truth_window(listener, covering=None, timeout=10.0):
    """
    Stamps between which truth was received (earlier truth was published unheard).

    With ``covering`` (seconds), first wait until truth reaches that stamp: a restarted
    emulator's truth publisher must be discovered again, which under load can take longer
    than its ranges take to arrive through the already running driver.
    """
    if covering is not None:
        listener.spin_until(lambda: bool(listener.truth) and to_seconds(
            listener.truth[-1].header.stamp) >= covering, timeout)
    listener.spin_until(lambda: False, 0.5)      # the truth of the newest cycle comes last
    return (to_seconds(listener.truth[0].header.stamp) + 0.15,
            to_seconds(listener.truth[-1].header.stamp))
