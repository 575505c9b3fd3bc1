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
``posture_estimator`` as separate processes talking over DDS, and watches them. On a
terminal it draws the true and the estimated boom a few times a second (``rich``'s live
display; the drawing is :mod:`epp_ros.cli.demo_view`): a side view and a top view, each
joint's predicted uncertainty around it, the anchors and the links the estimator judged
NLOS, and below them the method, the learned noise, the health level and its reason, the
links judged NLOS, the rate, the latency and the frames left unanswered.
With ``--plain``, or when the output is not a terminal, it prints one line a second
instead. Stops on Ctrl-C, after ``--duration`` or ``--postures``, shuts every process
down, prints a summary (``--json``: as the last stdout line) and can save a plot of the
estimated and true boom (``--plot FILE.png``).

``--field NAMES`` runs the emulator with the field simulator's effects (presets of
:data:`epp_ros.core.simulation.simulate.FIELD_EFFECTS`, comma-separated) instead of the
``--sigma/--nlos/--drop`` noise; ``--record BAG`` keeps the demo's topics in a rosbag2
(``epp_bag record`` beside the pipeline).

The view never slows the pipeline: the nodes are processes of their own, the demo takes
every message before it redraws and skips a redraw when it is behind, and the latency is
measured from a frame's stamp to the moment DDS received its posture, not to when the
demo got round to it.
"""
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

from epp_ros.cli.arguments import (DURATION_S, field_names, FRACTION, image_path_problem, integer,
                                   new_path_problem, NOISE_M, Parser, RATE_HZ, SEED,
                                   settle_noise_options)
from epp_ros.nodes.stopping import ignore_signals, shutdown_on_signals, ShutdownRequest

# Only the standard library and the stop request above are imported before main() has
# made SIGINT a request: rclpy, numpy and rich load inside the functions.

LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
LEVEL_STYLES = {'OK': 'bold green', 'WARN': 'bold yellow', 'ERROR': 'bold red',
                'STALE': 'bold magenta'}
#: The noise options' defaults (None when parsed: --field refuses them when given).
NOISE_DEFAULTS = {'sigma': 0.1, 'drop': 0.05, 'nlos': 0.0}
LIVE_PERIOD = 0.2           # s between redraws of the live view
PLAIN_PERIOD = 1.0          # s between the lines of --plain
RATE_WINDOW = 2.0           # s of postures the live view's rate counts
INFO_LINES = 6              # lines of the live view besides the drawing
STOP_WAIT = 5.0             # s a node gets to stop after SIGINT
RECORD_WAIT = 120.0         # s the recorder gets to write its bag


def parse_args(argv):
    from epp_ros.core import RANGE_METHODS
    from epp_ros.core.simulation import FIELD_EFFECTS
    parser = Parser(prog='epp_demo', description=__doc__.lstrip().splitlines()[0])
    parser.add_argument('--method', choices=RANGE_METHODS, default='cepp')
    parser.add_argument('--duration', type=DURATION_S, default=None,
                        help='seconds to run (default: until Ctrl-C)')
    parser.add_argument('--postures', type=integer(1, 10 ** 9), default=None,
                        help='stop once this many postures arrived (or --duration is over)')
    parser.add_argument('--rate', type=RATE_HZ, default=10.0, help='ranging cycles per second')
    parser.add_argument('--sigma', type=NOISE_M,
                        help=f'range noise, metres (default {NOISE_DEFAULTS["sigma"]:g})')
    parser.add_argument('--drop', type=FRACTION,
                        help=f'link dropout probability (default {NOISE_DEFAULTS["drop"]:g})')
    parser.add_argument('--nlos', type=FRACTION, help='fraction of NLOS links (default 0)')
    parser.add_argument('--field', metavar='EFFECT[,EFFECT...]', type=field_names,
                        help='the emulator simulates these field effects instead of '
                             '--sigma/--nlos/--drop: ' + ', '.join(FIELD_EFFECTS))
    parser.add_argument('--garbage', type=FRACTION, default=0.01,
                        help='probability of a corrupted line')
    parser.add_argument('--seed', type=SEED, default=0)
    parser.add_argument('--config', help='pump description (default: the packaged one)')
    parser.add_argument('--calibrated', metavar='PUMP.yaml',
                        help='driver and estimator start from this pump description (e.g. '
                             "epp_calibrate's), the emulator still simulates --config's")
    parser.add_argument('--plot', metavar='FILE.png', help='save estimated vs. true boom')
    parser.add_argument('--record', metavar='BAG',
                        help="record the demo's topics into this rosbag2 (a new directory)")
    parser.add_argument('--plain', action='store_true',
                        help='one line of numbers a second instead of the live view')
    parser.add_argument('--json', action='store_true',
                        help='print a JSON summary as the last stdout line')
    args = parser.parse_args(argv)
    settle_noise_options(parser, args, NOISE_DEFAULTS)
    problem = _output_problem(args)
    if problem:
        parser.error(problem)
    return args


def _output_problem(args):
    """Say what is wrong with --plot or --record before anything runs, or return None."""
    return ((args.plot and image_path_problem('--plot', args.plot))
            or (args.record and new_path_problem('--record', args.record)) or None)


class Monitor:
    """Receives ranges, postures, truth and diagnostics, and scores the postures."""

    def __init__(self):
        from diagnostic_msgs.msg import DiagnosticArray
        from epp_ros.app import contract
        from epp_ros.nodes.messages import POSTURE_QOS, RANGES_QOS, TRUTH_QOS
        from geometry_msgs.msg import PoseArray
        import rclpy
        from sensor_msgs.msg import JointState
        self.node = rclpy.create_node('epp_demo_monitor')
        self.truth_stamps, self.truths = [], []
        self.frame_stamps = []
        self.latencies, self.rmses, self.max_error = [], [], 0.0
        self.posture_stamps = []
        self.posture_times = []               # monotonic receipt of each posture
        self.last = None                      # (estimate, truth) of the newest posture
        self.estimate = None                  # the newest posture, with or without truth
        self.level = None
        self.reason = ''
        self.values = {}                      # the estimator's newest diagnostic values
        self.received = 0                     # messages taken so far
        self.node.create_subscription(PoseArray, contract.POSTURE.name, self.on_posture,
                                      POSTURE_QOS)
        self.node.create_subscription(PoseArray, contract.TRUTH.name, self.on_truth,
                                      TRUTH_QOS)
        self.node.create_subscription(JointState, contract.RANGES.name, self.on_ranges,
                                      RANGES_QOS)
        self.node.create_subscription(DiagnosticArray, contract.DIAGNOSTICS.name,
                                      self.on_diagnostics, contract.DIAGNOSTICS.depth)

    def on_truth(self, message):
        from epp_ros.app import contract
        from epp_ros.nodes.messages import to_seconds
        self.received += 1
        self.truth_stamps.append(to_seconds(message.header.stamp))
        self.truths.append(contract.points_of(message))

    def on_ranges(self, message):
        self.received += 1
        self.frame_stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))

    def on_posture(self, message, info):
        """
        Score a posture against the truth of its frame.

        Its latency ends when DDS received it (``info``), not when the demo took it: a
        redraw that keeps the demo busy does not count.
        """
        from epp_ros.app import contract
        from epp_ros.core.estimation import frame_rmse, joint_errors
        from epp_ros.nodes.messages import to_seconds
        import numpy as np
        self.received += 1
        received_ns = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
        received = 1e-9 * received_ns if received_ns > 0 else time.time()
        stamp = to_seconds(message.header.stamp)
        self.posture_stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))
        self.posture_times.append(time.monotonic())
        self.latencies.append(received - stamp)
        estimate = contract.points_of(message)
        self.estimate = estimate
        # The truth of a frame is the newest published before the frame was received.
        index = int(np.searchsorted(self.truth_stamps, stamp)) - 1
        if index >= 0 and stamp - self.truth_stamps[index] < 1.0:
            truth = self.truths[index]
            self.rmses.append(float(frame_rmse(estimate[1:], truth[1:])))
            self.max_error = max(self.max_error,
                                 float(joint_errors(estimate[1:], truth[1:]).max()))
            self.last = (estimate, truth)

    def on_diagnostics(self, message):
        self.received += 1
        for status in message.status:
            if status.name.startswith('posture_estimator'):
                self.level = LEVEL_NAMES.get(ord(status.level), '?')
                self.reason = status.message
                self.values = {value.key: value.value for value in status.values}

    def drain(self, executor, budget=0.1):
        """Take every message waiting, for at most ``budget`` s; True when none is left."""
        deadline = time.monotonic() + budget
        while time.monotonic() < deadline:
            before = self.received
            executor.spin_once(timeout_sec=0.0)
            if self.received == before:
                return True
        return False

    def joint_stds(self, joints):
        """Each joint's standard deviation from the diagnostics, metres (NaN where unknown)."""
        from epp_ros.app.health import joint_stds
        return joint_stds(self.values, joints)

    def recent_rate(self, window=RATE_WINDOW):
        """Return the postures per second over the last ``window`` seconds."""
        now = time.monotonic()
        recent = sum(1 for t in self.posture_times[-int(100 * window):] if now - t <= window)
        return recent / window

    def unanswered_frames(self):
        """
        Count the range frames that got no posture.

        Counted between the first posture (before it the estimator may not have been
        listening yet) and the newest: the estimator takes frames in order, so a frame
        older than the newest posture without one of its own was refused or lost, while a
        newer one may still be on its way (a loaded machine), and is not counted.
        """
        if not self.posture_stamps:
            return len(self.frame_stamps)
        answered = set(self.posture_stamps)
        first, last = min(self.posture_stamps), max(self.posture_stamps)
        return sum(1 for stamp in self.frame_stamps
                   if first <= stamp <= last and stamp not in answered)

    def summary(self, method):
        from epp_ros.core.estimation import pooled_rmse
        import numpy as np
        latencies = 1e3 * np.array(self.latencies) if self.latencies else np.full(1, np.nan)
        return {'frames': len(self.posture_stamps), 'rmse_m': pooled_rmse(self.rmses),
                'max_joint_error_m': self.max_error,
                'latency_p50_ms': float(np.median(latencies)),
                'latency_p99_ms': float(np.percentile(latencies, 99)),
                'dropped_frames': self.unanswered_frames(), 'method': method}


def nlos_line(values, width=None):
    """
    Return the live view's line of NLOS links from the estimator's diagnostic values.

    ``NLOS links 3: joint 2-anchor 3, joint 5-anchors 1 4``: the count, then the links by
    joint; when that is wider than ``width``, ``NLOS links 3 (joint-anchor): 2-3 5-1 5-4``.
    """
    from epp_ros.app.health import NLOS_FLAGGED, nlos_pairs
    count = values.get('NLOS links', '-')
    pairs = nlos_pairs(values.get(NLOS_FLAGGED))
    if not pairs:
        return f'NLOS links {count}'
    anchors = {}
    for joint, anchor in pairs:
        anchors.setdefault(joint, []).append(str(anchor))
    line = f'NLOS links {count}: ' + ', '.join(
        f'joint {k}-anchor{"s" if len(js) > 1 else ""} {" ".join(js)}'
        for k, js in anchors.items())
    if width is None or len(line) <= width:
        return line
    return f'NLOS links {count} (joint-anchor): ' + ' '.join(f'{k}-{j}' for k, j in pairs)


def _noise_text(args):
    if args.field:
        return f'field={args.field}'
    return f'sigma={args.sigma} m  drop={args.drop}  nlos={args.nlos}'


def render(monitor, args, elapsed):
    """Render the numbers as text; ``--plain`` prints its last line."""
    from epp_ros.core.estimation import joint_errors
    lines = [f'epp_demo  method={args.method}  {_noise_text(args)}  '
             f'{elapsed:5.1f} s   (Ctrl-C to stop)', '',
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


def live_view(monitor, args, elapsed, width, height, scene, skipped=0):
    """
    Return the live view as a ``rich`` renderable: the drawing and the numbers below it.

    ``scene`` is a dict with ``axis`` (the slew axis, x y), ``span`` (the boom's length)
    and ``top`` (its highest reach), metres, which keep the picture still, and ``anchors``
    (their positions, (m, 3) metres), drawn in the top view with the links judged NLOS.
    """
    from epp_ros.app.health import NLOS_FLAGGED, nlos_pairs
    from epp_ros.cli import demo_view
    from rich.console import Group
    from rich.text import Text
    summary = monitor.summary(args.method)
    estimate, truth = monitor.last if monitor.last is not None else (monitor.estimate, None)
    values = monitor.values
    nlos = nlos_pairs(values.get(NLOS_FLAGGED))
    header = Text.assemble(('epp_demo', 'bold'), '  method ', (args.method, 'bold cyan'),
                           f'  {_noise_text(args)}  {elapsed:.1f} s  Ctrl-C stops')
    lines = [header]
    drawing_height = max(height - INFO_LINES, 4)
    if estimate is None:
        lines.append(Text('waiting for the first posture ...'))
        lines += [Text('')] * (drawing_height - 1)
    else:
        stds = monitor.joint_stds(len(estimate) - 1)
        drawing = demo_view.draw(estimate, truth, stds, width=max(width - 1, 20),
                                 height=drawing_height, nlos=nlos, **scene)
        lines.append(demo_view.to_rich(drawing))
    glyphs, styles = demo_view.GLYPHS, demo_view.STYLES
    lines.append(Text.assemble(
        'estimate ', (f'{glyphs["pivot"]} 1 2 .. {glyphs["tip"]}', styles['estimate']),
        '  truth ', (f'{glyphs["truth_joint"]} {glyphs["truth_line"]}', styles['truth']),
        '  ', (glyphs['uncertainty'], styles['uncertainty']),
        f' {demo_view.SIGMAS:g}σ x{demo_view.MAGNIFY:g}  ',
        (glyphs['ground'], styles['ground']), ' ground  ',
        (glyphs['anchor'], styles['anchor']), ' anchor  ',
        (glyphs['nlos'], styles['nlos']), ' NLOS link'))
    level = monitor.level or '-'
    lines.append(Text.assemble('health ', (level, LEVEL_STYLES.get(level, 'bold')),
                               f'  {monitor.reason or "waiting for /diagnostics"}'))
    lines.append(Text(f'learned noise  σ {values.get("range sigma [m]", "-")} m   '
                      f'NLOS fraction {values.get("NLOS fraction", "-")}'))
    lines.append(Text(nlos_line(values, width), style=styles['nlos'] if nlos else ''))
    lines.append(Text(
        f'{monitor.recent_rate():.1f} Hz  latency p50 {summary["latency_p50_ms"]:.1f} ms '
        f'p99 {summary["latency_p99_ms"]:.1f} ms  unanswered frames '
        f'{summary["dropped_frames"]}  RMSE {summary["rmse_m"]:.3f} m'
        + (f'  redraws skipped {skipped}' if skipped else '')))
    for line in lines:
        line.no_wrap, line.overflow = True, 'crop'
    return Group(*lines)


def plot(monitor, path):
    """Save the newest estimated and true boom, side view along the slew, as a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    from epp_ros.core.estimation import pooled_rmse
    from matplotlib import pyplot
    import numpy as np
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


def emulator_noise(args):
    """Return the emulator's noise options: ``--field`` or ``--sigma/--drop/--nlos``."""
    if args.field:
        return ['--field', args.field]
    return ['--sigma', str(args.sigma), '--drop', str(args.drop), '--nlos', str(args.nlos)]


def pipeline_commands(args, config_path, link):
    """
    Return the command lines of the emulator, the driver and the estimator.

    The emulator simulates the pump of ``config_path`` (with ``--field``'s effects, drawn
    from ``--seed``); driver and estimator start from ``--calibrated`` when given (e.g.
    what ``epp_calibrate`` wrote from a recording of this demo), else from the same file.
    """
    python = [sys.executable, '-m']
    emulator = python + ['epp_ros.nodes.emulator', '--protocol', 'json', '--pty', '--link',
                         link, '--truth', '--config', str(config_path), '--rate',
                         str(args.rate), *emulator_noise(args), '--garbage', str(args.garbage),
                         '--seed', str(args.seed)]
    ros = ['--ros-args', '--params-file', str(args.calibrated or config_path),
           '--log-level', 'warn']
    driver = python + ['epp_ros.nodes.driver', *ros, '-p', f'port:={link}',
                       '-p', 'protocol:=json']
    estimator = python + ['epp_ros.nodes.estimator', *ros, '-p', f'method:={args.method}']
    return emulator, driver, estimator


def start_pipeline(args, config_path, workdir, stderr=None):
    """Emulator, driver and estimator processes; ``stderr`` a file for their output."""
    emulator, *nodes = pipeline_commands(args, config_path, str(Path(workdir) / 'ttyUWB'))
    emulator = subprocess.Popen(emulator, stdout=subprocess.PIPE, stderr=stderr, text=True)
    processes = [emulator]
    announced = emulator.stdout.readline().split()
    if not announced or announced[0] != 'PTY':
        return processes, False
    processes += [subprocess.Popen(command, stderr=stderr) for command in nodes]
    return processes, True


def start_recorder(path, stderr=None):
    """Start ``epp_bag record`` on the demo's topics (ranges, postures, truth, diagnostics)."""
    return subprocess.Popen([sys.executable, '-m', 'epp_ros.cli.bag', 'record', str(path)],
                            stdout=subprocess.PIPE, stderr=stderr, text=True)


def stop(processes, wait=STOP_WAIT):
    """
    Ask every process to end (SIGTERM); kill what has not ended after ``wait`` seconds.

    SIGTERM, not SIGINT: the nodes take both alike, and one still starting Python, before
    its handlers are in, ends silently on SIGTERM (SIGINT would print a KeyboardInterrupt).
    """
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(wait)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _done(args, monitor, elapsed):
    """Judge whether ``--duration`` is over or ``--postures`` postures arrived."""
    if args.postures is not None and len(monitor.posture_stamps) >= args.postures:
        return True
    return args.duration is not None and elapsed >= args.duration


def main(argv=None):
    """
    Run the demo; return the exit status.

    SIGINT and SIGTERM only ask it to stop from the first line on (``stopping``), so that a
    Ctrl-C at any moment ends with the summary and a restored terminal. Run as a program
    (``argv`` None) the signals are then ignored while the interpreter exits; called with
    ``argv`` the caller's handlers are put back.
    """
    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    ShutdownRequest.requested = False
    stop_request = shutdown_on_signals()
    try:
        args = parse_args(sys.argv[1:] if argv is None else argv)
        if sys.stdout is None:                      # started with stdout closed
            print('epp_demo: stdout is closed: nowhere to show the demo', file=sys.stderr)
            return 2
        return run(args, stop_request)
    except BrokenPipeError:                         # `epp_demo | head -1`: the reader left
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:                          # stdout on a full disk, /dev/full
        print(f'epp_demo: cannot write the output: {exc.strerror or exc}', file=sys.stderr)
        return 2
    finally:
        if argv is None:
            ignore_signals()
        else:
            for signum, handler in handlers.items():
                signal.signal(signum, handler)


def run(args, stop_request):
    """Run the pipeline and the view until asked to stop or ``--duration`` is over."""
    from epp_ros.app.config import ConfigError, default_config_path, load_pump_config
    try:
        config_path = Path(args.config) if args.config else default_config_path()
        config = load_pump_config(config_path)
        if args.calibrated:         # what driver and estimator are told, and the view draws
            config = load_pump_config(args.calibrated)
    except ConfigError as exc:
        print(f'epp_demo: {exc}', file=sys.stderr)
        return 2
    view = sys.stderr if args.json else sys.stdout
    live = view.isatty() and not args.plain
    workdir = tempfile.TemporaryDirectory(prefix='epp_demo_')
    # The live view owns the screen: the nodes' own messages go to a file meanwhile.
    log = open(Path(workdir.name) / 'pipeline.log', 'w+') if live else None
    monitor, failure, recorder = _monitored(args, config, config_path, workdir.name, log, view,
                                            live, stop_request)
    result = monitor.summary(args.method)
    if args.plot and monitor.last is not None:
        plot(monitor, args.plot)
    if failure:
        print(f'epp_demo: {failure}', file=sys.stderr)
        if log is not None:
            log.seek(0)
            sys.stderr.write(''.join(log.readlines()[-20:]))
    if log is not None:
        log.close()
    workdir.cleanup()
    _summarise(args, view, recorder, result)
    if recorder is not None and recorder.returncode != 0:
        print(f'epp_demo: the recording failed (epp_bag record exited {recorder.returncode})',
              file=sys.stderr)
        return 2
    return 2 if failure else 0


def _monitored(args, config, config_path, workdir, log, view, live, stop_request):
    """
    Start the pipeline (and recorder), watch it until stopped, stop it.

    Returns
    -------
    monitor : Monitor
    failure : str or None
    recorder : subprocess.Popen or None

    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    monitor = Monitor()
    executor = SingleThreadedExecutor()
    executor.add_node(monitor.node)
    processes, recorder, failure = [], None, None
    try:
        if args.record:
            recorder = start_recorder(args.record, log)
        processes, started = start_pipeline(args, config_path, workdir, log)
        if not started and not stop_request.requested:
            failure = 'the emulator did not start'
        elif started:
            scene = {'axis': tuple(config.base[:2]), 'span': float(sum(config.arm_lengths)),
                     'top': float(config.base[2] + sum(config.arm_lengths)),
                     'anchors': tuple(config.anchor_positions)}
            failure = watch(monitor, executor, processes, args, view, live, scene,
                            stop_request)
    finally:
        stop(processes)
        if recorder is not None:
            stop([recorder], RECORD_WAIT)
    executor.remove_node(monitor.node)
    executor.shutdown(timeout_sec=0)    # before the context: its __del__ would touch it after
    monitor.node.destroy_node()
    rclpy.try_shutdown()
    return monitor, failure, recorder


def _summarise(args, view, recorder, result):
    """Print the recorder's output and the run's summary line (and JSON with ``--json``)."""
    if recorder is not None:
        view.write(recorder.stdout.read())
        recorder.stdout.close()
    view.write(f'\nepp_demo: {result["frames"]} postures, RMSE {result["rmse_m"]:.3f} m, max '
               f'joint error {result["max_joint_error_m"]:.3f} m, latency p50 '
               f'{result["latency_p50_ms"]:.1f} ms / p99 {result["latency_p99_ms"]:.1f} ms, '
               f'{result["dropped_frames"]} range frames without a posture\n')
    view.flush()
    if args.json:
        print(json.dumps(result))


def watch(monitor, executor, processes, args, view, live, scene, stop_request):
    """
    Take the messages and show them until stopped; return a failure or None.

    Every message is taken before a redraw; when messages keep coming for longer than a
    redraw's budget the redraw is skipped, never a message.
    """
    live_display = None
    if live:
        from rich.console import Console
        from rich.live import Live
        console = Console(file=view)
        live_display = Live(console=console, screen=True, auto_refresh=False,
                            redirect_stdout=False, redirect_stderr=False)
        live_display.start()
    skipped = 0
    start = last_render = time.monotonic()
    failure = None
    try:
        while not stop_request.requested and not _done(args, monitor, time.monotonic() - start):
            executor.spin_once(timeout_sec=0.05)
            if any(p.poll() is not None for p in processes):
                time.sleep(0.2)         # a Ctrl-C reaches the nodes too: was it one?
                if not stop_request.requested:
                    failure = 'a pipeline process exited early'
                break
            now = time.monotonic()
            if now - last_render < (LIVE_PERIOD if live else PLAIN_PERIOD):
                continue
            last_render = now
            if not live:
                view.write(render(monitor, args, now - start).splitlines()[-1].strip() + '\n')
                view.flush()
            elif not monitor.drain(executor):
                skipped += 1
            else:
                size = live_display.console.size
                live_display.update(live_view(monitor, args, now - start, size.width,
                                              size.height, scene, skipped), refresh=True)
    finally:
        if live_display is not None:
            live_display.stop()
    return failure


if __name__ == '__main__':
    sys.exit(main())
