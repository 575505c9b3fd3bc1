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
epp_demo: the whole pipeline live on the built-in simulated pump.

Starts ``uwb_emulator`` (a pseudo-terminal, with the true posture), ``uwb_driver`` and
``posture_estimator`` as separate processes talking over DDS, and watches them: each joint's
estimate and its error against the truth, the running RMSE, the frame rate, the latency from
a range frame to its posture, and the estimator's diagnostic level. Stops on Ctrl-C or after
``--duration``, shuts every process down, prints a summary (``--json``: as the last stdout
line) and can save a plot of the estimated and true boom (``--plot FILE.png``).
"""
import json
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
from epp_ros import contract
from epp_ros.arguments import Parser
from epp_ros.config import ConfigError, default_config_path, load_pump_config
from epp_ros.core import RANGE_METHODS
from epp_ros.core.metrics import frame_rmse, joint_errors, pooled_rmse
from epp_ros.nodes.common import POSTURE_QOS, RANGES_QOS, to_seconds
from geometry_msgs.msg import PoseArray
import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


def parse_args(argv):
    parser = Parser(prog='epp_demo', description=__doc__.lstrip().splitlines()[0])
    parser.add_argument('--method', choices=RANGE_METHODS, default='cepp')
    parser.add_argument('--duration', type=float, default=None,
                        help='seconds to run (default: until Ctrl-C)')
    parser.add_argument('--rate', type=float, default=10.0, help='ranging cycles per second')
    parser.add_argument('--sigma', type=float, default=0.1, help='range noise, metres')
    parser.add_argument('--drop', type=float, default=0.05, help='link dropout probability')
    parser.add_argument('--nlos', type=float, default=0.0, help='fraction of NLOS links')
    parser.add_argument('--garbage', type=float, default=0.01,
                        help='probability of a corrupted line')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--config', help='pump description (default: the packaged one)')
    parser.add_argument('--plot', metavar='FILE.png', help='save estimated vs. true boom')
    parser.add_argument('--json', action='store_true',
                        help='print a JSON summary as the last stdout line')
    args = parser.parse_args(argv)
    if args.rate <= 0 or (args.duration is not None and args.duration <= 0):
        parser.error('--rate and --duration must be positive')
    return args


class Monitor(Node):
    """Receives ranges, postures, truth and diagnostics, and scores the postures."""

    def __init__(self):
        super().__init__('epp_demo_monitor')
        self.truth_stamps, self.truths = [], []
        self.frame_stamps = []
        self.latencies, self.rmses, self.max_error = [], [], 0.0
        self.posture_stamps = []
        self.last = None                      # (estimate, truth) of the newest posture
        self.level = None
        self.create_subscription(PoseArray, contract.POSTURE.name, self.on_posture,
                                 POSTURE_QOS)
        self.create_subscription(PoseArray, contract.TRUTH.name, self.on_truth, POSTURE_QOS)
        self.create_subscription(JointState, contract.RANGES.name, self.on_ranges, RANGES_QOS)
        self.create_subscription(DiagnosticArray, contract.DIAGNOSTICS.name,
                                 self.on_diagnostics, contract.DIAGNOSTICS.depth)

    def on_truth(self, message):
        self.truth_stamps.append(to_seconds(message.header.stamp))
        self.truths.append(contract.points_of(message))

    def on_ranges(self, message):
        self.frame_stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))

    def on_posture(self, message):
        received = time.time()
        stamp = to_seconds(message.header.stamp)
        self.posture_stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))
        self.latencies.append(received - stamp)
        estimate = contract.points_of(message)
        # The truth of a frame is the newest published before the frame was received.
        index = int(np.searchsorted(self.truth_stamps, stamp)) - 1
        if index >= 0 and stamp - self.truth_stamps[index] < 1.0:
            truth = self.truths[index]
            self.rmses.append(float(frame_rmse(estimate[1:], truth[1:])))
            self.max_error = max(self.max_error,
                                 float(joint_errors(estimate[1:], truth[1:]).max()))
            self.last = (estimate, truth)

    def on_diagnostics(self, message):
        for status in message.status:
            if status.name.startswith('posture_estimator'):
                self.level = LEVEL_NAMES.get(ord(status.level), '?')

    def unanswered_frames(self, settle=0.5):
        """
        Count the range frames that got no posture.

        Counted from the first posture on (before it the estimator may not have been
        listening yet) to ``settle`` s ago.
        """
        if not self.posture_stamps:
            return len(self.frame_stamps)
        answered = set(self.posture_stamps)
        first = min(self.posture_stamps)
        horizon = time.time() - settle
        return sum(1 for stamp in self.frame_stamps
                   if first <= stamp and stamp[0] + 1e-9 * stamp[1] < horizon
                   and stamp not in answered)

    def summary(self, method):
        latencies = 1e3 * np.array(self.latencies) if self.latencies else np.full(1, np.nan)
        return {'frames': len(self.posture_stamps), 'rmse_m': pooled_rmse(self.rmses),
                'max_joint_error_m': self.max_error,
                'latency_p50_ms': float(np.median(latencies)),
                'latency_p99_ms': float(np.percentile(latencies, 99)),
                'dropped_frames': self.unanswered_frames(), 'method': method}


def render(monitor, args, elapsed):
    """Render the live view as text."""
    lines = [f'epp_demo  method={args.method}  sigma={args.sigma} m  drop={args.drop}  '
             f'nlos={args.nlos}  {elapsed:5.1f} s   (Ctrl-C to stop)', '',
             '  joint      x [m]      y [m]      z [m]    error [m]']
    if monitor.last is not None:
        estimate, truth = monitor.last
        errors = joint_errors(estimate, truth)
        for k, (position, error) in enumerate(zip(estimate, errors)):
            name = 'base' if k == 0 else f'{k:4d}'
            lines.append(f'  {name:>5} {position[0]:10.2f} {position[1]:10.2f} '
                         f'{position[2]:10.2f} {error:12.3f}')
    else:
        lines.append('  waiting for the first posture ...')
    summary = monitor.summary(args.method)
    rate = len(monitor.posture_stamps) / max(elapsed, 1e-9)
    lines += ['', f'  postures {summary["frames"]}   {rate:.1f} Hz   running RMSE '
              f'{summary["rmse_m"]:.3f} m   latency p50 {summary["latency_p50_ms"]:.1f} ms  '
              f'p99 {summary["latency_p99_ms"]:.1f} ms   diagnostics {monitor.level or "-"}   '
              f'unanswered frames {summary["dropped_frames"]}']
    return '\n'.join(lines)


def plot(monitor, path):
    """Save the newest estimated and true boom, side view along the slew, as a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    estimate, truth = monitor.last
    figure, axis = pyplot.subplots(figsize=(7, 5))
    for joints, style, label in ((truth, 'k-o', 'truth'), (estimate, 'C1--s', 'estimate')):
        reach = np.linalg.norm(joints[:, :2] - joints[0, :2], axis=1)
        axis.plot(reach, joints[:, 2], style, label=label)
    axis.set_xlabel('horizontal reach from the slew axis [m]')
    axis.set_ylabel('height [m]')
    axis.set_title(f'epp_demo: boom posture, RMSE {pooled_rmse(monitor.rmses):.3f} m')
    axis.set_aspect('equal')
    axis.grid(True)
    axis.legend()
    figure.savefig(path, dpi=100, bbox_inches='tight')
    pyplot.close(figure)


def start_pipeline(args, config_path, workdir):
    """Emulator, driver and estimator processes; the emulator's device path."""
    python = [sys.executable, '-m']
    link = str(Path(workdir) / 'ttyUWB')
    emulator = subprocess.Popen(
        python + ['epp_ros.nodes.emulator', '--protocol', 'json', '--pty', '--link', link,
                  '--truth', '--config', str(config_path), '--rate', str(args.rate),
                  '--sigma', str(args.sigma), '--drop', str(args.drop), '--nlos',
                  str(args.nlos), '--garbage', str(args.garbage), '--seed', str(args.seed)],
        stdout=subprocess.PIPE, text=True)
    announced = emulator.stdout.readline().split()
    if not announced or announced[0] != 'PTY':
        raise RuntimeError('the emulator did not start')
    ros = ['--ros-args', '--params-file', str(config_path), '--log-level', 'warn']
    driver = subprocess.Popen(python + ['epp_ros.nodes.driver', *ros, '-p', f'port:={link}',
                                        '-p', 'protocol:=json'])
    estimator = subprocess.Popen(python + ['epp_ros.nodes.estimator', *ros,
                                           '-p', f'method:={args.method}'])
    return [emulator, driver, estimator]


def stop(processes):
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
    for process in processes:
        try:
            process.wait(5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        if process.stdout is not None:
            process.stdout.close()


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        config_path = Path(args.config) if args.config else default_config_path()
        load_pump_config(config_path)
    except ConfigError as exc:
        print(f'epp_demo: {exc}', file=sys.stderr)
        return 2
    view = sys.stderr if args.json else sys.stdout
    live = view.isatty()
    workdir = tempfile.TemporaryDirectory(prefix='epp_demo_')
    rclpy.init()
    monitor = Monitor()
    processes = []
    try:
        processes = start_pipeline(args, config_path, workdir.name)
        start = last_render = time.monotonic()
        while args.duration is None or time.monotonic() - start < args.duration:
            rclpy.spin_once(monitor, timeout_sec=0.05)
            if any(p.poll() is not None for p in processes):
                print('epp_demo: a pipeline process exited early', file=sys.stderr)
                break
            now = time.monotonic()
            if now - last_render >= (0.2 if live else 1.0):
                last_render = now
                text = render(monitor, args, now - start)
                view.write('\033[H\033[J' + text + '\n' if live
                           else text.splitlines()[-1].strip() + '\n')
                view.flush()
    except KeyboardInterrupt:
        pass
    finally:
        stop(processes)
    result = monitor.summary(args.method)
    if args.plot and monitor.last is not None:
        plot(monitor, args.plot)
    monitor.destroy_node()
    rclpy.try_shutdown()
    workdir.cleanup()
    view.write(f'\nepp_demo: {result["frames"]} postures, RMSE {result["rmse_m"]:.3f} m, max '
               f'joint error {result["max_joint_error_m"]:.3f} m, latency p50 '
               f'{result["latency_p50_ms"]:.1f} ms / p99 {result["latency_p99_ms"]:.1f} ms, '
               f'{result["dropped_frames"]} range frames without a posture\n')
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
