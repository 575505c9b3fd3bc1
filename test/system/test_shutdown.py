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
Every node ends cleanly (status 0, no traceback) on SIGINT and SIGTERM, however many come.

``ros2 launch`` forwards a terminal's Ctrl-C to nodes that already got it, so a second
SIGINT follows the first within milliseconds; it escalates to SIGTERM. Each case waits for
a condition (a log line, the handlers being installed) with a generous timeout, never for a
fixed time, and then signals at the moment under test.
"""
import os
import random
import signal
import subprocess
import threading
import time

import pytest
from ros_processes import PUMP_YAML, script

TIMEOUT = 30.0          # s: for anything to happen on a busy 2-core machine
#: How each node is started and the line (stdout or stderr) that says it is spinning.
NODES = {
    'driver': (lambda port: [script('uwb_driver'), '--ros-args', '--params-file',
                             str(PUMP_YAML), '-p', f'port:={port}', '-p', 'protocol:=json'],
               'reading'),
    'estimator': (lambda port: [script('posture_estimator'), '--ros-args', '--params-file',
                                str(PUMP_YAML)], 'cepp on'),
    'emulator': (lambda port: [script('uwb_emulator'), '--protocol', 'json', '--pty',
                               '--truth', '--rate', '50'], 'PTY'),
}
JSON_LINE = b'{"tag":"1","links":[{"A":"1782","R":"2.3"},{"A":"1783","R":"4.1"}]}\r\n'


class Fed:
    """A pseudo-terminal that a thread feeds with range lines, so the driver is busy."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        os.set_blocking(self.master, False)     # once nobody reads, a full buffer must not hang
        self.path = os.ttyname(self.slave)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._feed, daemon=True)
        self.thread.start()

    def _feed(self):
        while not self.stop.wait(0.01):
            try:
                os.write(self.master, JSON_LINE)
            except OSError:         # nobody reads and the buffer is full: keep going
                pass

    def close(self):
        self.stop.set()
        self.thread.join()
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def pty_port():
    fed = Fed()
    yield fed.path
    fed.close()


class Watched:
    """A node process whose output lines are collected as they come."""

    def __init__(self, args):
        self.process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)
        self.lines = {'stdout': [], 'stderr': []}
        self.readers = [threading.Thread(target=self._collect, args=(name,), daemon=True)
                        for name in self.lines]
        for reader in self.readers:
            reader.start()

    def _collect(self, name):
        for line in getattr(self.process, name):
            self.lines[name].append(line)

    def wait_for_line(self, text):
        return wait_until(lambda: any(text in line for lines in self.lines.values()
                                      for line in lines) or self.process.poll() is not None)

    def handlers_installed(self):
        """Whether the node catches SIGTERM: its own handlers are in (run_node started)."""
        try:
            with open(f'/proc/{self.process.pid}/status') as status:
                caught = next(line for line in status if line.startswith('SigCgt'))
        except (OSError, StopIteration):
            return False
        return bool(int(caught.split()[1], 16) & (1 << (signal.SIGTERM - 1)))

    def finish(self):
        """Exit status and stderr, once the process has ended (killed if it hangs)."""
        try:
            status = self.process.wait(TIMEOUT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            status = 'hung'
            self.process.wait()
        for reader in self.readers:
            reader.join(TIMEOUT)
        self.process.stdout.close()
        self.process.stderr.close()
        return status, ''.join(self.lines['stderr'])


def wait_until(condition, timeout=TIMEOUT):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def send(process, schedule):
    """Send (delay before, signal) pairs."""
    for delay, signum in schedule:
        time.sleep(delay)
        process.send_signal(signum)


def start(node, port):
    args, ready = NODES[node]
    return Watched(args(port)), ready


def assert_clean(watched, schedule):
    status, stderr = watched.finish()
    assert status == 0, (schedule, stderr)
    assert 'Traceback' not in stderr, (schedule, stderr)


@pytest.mark.parametrize('node', list(NODES))
@pytest.mark.parametrize('schedule', [
    [(0.0, signal.SIGINT), (0.03, signal.SIGINT)],      # launch's second SIGINT
    [(0.0, signal.SIGTERM)],
], ids=['sigint-twice', 'sigterm'])
def test_a_running_node_ends_cleanly(node, schedule, pty_port):
    watched, ready = start(node, pty_port)
    assert watched.wait_for_line(ready) and watched.process.poll() is None, \
        ''.join(watched.lines['stderr'])
    send(watched.process, schedule)
    assert_clean(watched, schedule)


def random_schedule(rng):
    """1 to 4 SIGINTs or SIGTERMs, within 50 ms of each other."""
    return [(rng.uniform(0.0, 0.05), rng.choice([signal.SIGINT, signal.SIGTERM]))
            for _ in range(rng.randint(1, 4))]


@pytest.mark.parametrize('node', list(NODES))
def test_signals_at_random_moments_end_cleanly(node, pty_port):
    """From the moment the node's handlers are in: during init, construction, spin."""
    rng = random.Random(f'shutdown-{node}')
    for _ in range(4):
        watched, _ = start(node, pty_port)
        assert wait_until(lambda: watched.handlers_installed()
                          or watched.process.poll() is not None)
        schedule = [(rng.uniform(0.0, 1.5), signal.SIGINT), *random_schedule(rng)]
        send(watched.process, schedule)
        assert_clean(watched, schedule)
