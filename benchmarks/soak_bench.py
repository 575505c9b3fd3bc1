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
python3 dev.py bench soak: a long stream through the parser, the assembler and the estimator.

In-process, ``frames`` ranging cycles of the packaged pump on a working cycle (10 Hz,
sigma = 0.1 m, 2 % dropouts) become device lines (:func:`epp_ros.uwb.emulation.cycle_lines`,
json protocol), which go through :class:`~epp_ros.uwb.decoder.LineDecoder`,
:class:`~epp_ros.uwb.frames.FrameAssembler` and
:class:`~epp_ros.core.PostureEstimator`, as uwb_driver and posture_estimator chain them.
Every frame the assembler closes gets a decision: a posture, or a rejection with its
reason (the integrity's or the solver's), which is a decision too. A frame is lost when
its cycle reached no decision: ``frames_lost = cycles sent - decisions`` (lines that were
not parsed, cycles the assembler did not close, frames whose update raised).

Live, a synthesised bag of ``live_frames`` frames is played with ``epp_bag play --fast``
into a posture_estimator process; ``frames_lost = frames played - frames received`` by the
node (its ``/diagnostics`` count), next to the postures this process received and the
frames the node reports unsolved.

Lagging, a bag is played in real time at 50 Hz into a posture_estimator that is stopped
(SIGSTOP) for ``lag_seconds`` in the middle: the frames its publisher could not keep for it
are lost on the way, and the node must count every one (``frames lost`` from the frames'
numbers): frames played = received + lost + before_first, exactly.

The resident set (VmRSS of ``/proc/<pid>/status``) is read at the start, after warm-up
(1 % of the frames) and at the end: of this process in-process, of the estimator process
live. The target is nothing lost and the end within 10 % of the warm-up value.
"""
from collections import Counter
from dataclasses import dataclass
import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time
import traceback

from epp_ros.app.config import default_config_path, load_pump_config
from epp_ros.core import PostureEstimator
from epp_ros.core.simulation import RangeNoise, working_cycle
from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.emulation import cycle_lines
from epp_ros.uwb.frames import FrameAssembler
import numpy as np

__all__ = ['rss_mb', 'soak_in_process', 'soak_live', 'soak_lag', 'SoakReport', 'run',
           'RSS_TOLERANCE']

RATE = 10.0                 #: ranging cycles per second of the simulated pump
WARMUP = 0.01               #: fraction of the frames after which RSS is the reference
RSS_TOLERANCE = 0.10        #: RSS at the end within this fraction of the warm-up value
#: Seconds of working cycle simulated once and then walked forth and back (continuous).
CHUNK_SECONDS = 600.0
#: Seconds without a new frame at the node, the player done, after which the rest is lost.
QUIET = 10.0


def rss_mb(pid='self'):
    """Return the resident set of a process in MB (VmRSS), or None if it cannot be read."""
    try:
        with open(f'/proc/{pid}/status') as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def _growth(warm, end):
    """Percent change from ``warm`` to ``end`` (None if either is unknown)."""
    if warm is None or end is None or warm <= 0:
        return None
    return 100.0 * (end - warm) / warm


def _cycle_index(i, n):
    """Walk ``0..n-1`` forth and back (0, 1, .., n-1, n-2, .., 0, 1, ..): no jump."""
    period = 2 * (n - 1)
    k = i % period
    return k if k < n else period - k


class _Memory:
    """
    The resident set of a process: at the start, after warm-up, its peak and at the end.

    The start is read when made, the warm-up value once :data:`WARMUP` of ``frames`` are
    done (:meth:`after`), the peak at each :meth:`sample`, the end at :meth:`finish`.
    """

    def __init__(self, frames, pid='self'):
        self.pid = pid
        self.warm_at = max(1, int(round(frames * WARMUP)))
        self.start = self.warm = rss_mb(pid)
        self.warmed = False
        self.peak = self.start or 0.0
        self.end = None

    def after(self, count):
        """Read the warm-up value, once, after ``count`` frames if they are enough."""
        if not self.warmed and count >= self.warm_at:
            self.warm, self.warmed = rss_mb(self.pid), True

    def sample(self):
        """Take a reading into the peak."""
        self.peak = max(self.peak, rss_mb(self.pid) or 0.0)

    def finish(self):
        """Read the end value."""
        self.end = rss_mb(self.pid)

    def fields(self):
        """Return ``rss_start_mb``, ``_warm_mb``, ``_end_mb``, ``_peak_mb``, ``rss_growth_pct``."""
        return {'rss_start_mb': self.start, 'rss_warm_mb': self.warm, 'rss_end_mb': self.end,
                'rss_peak_mb': max(self.peak, self.end or 0.0),
                'rss_growth_pct': _growth(self.warm, self.end)}


class _Pipeline:
    """Decoder, assembler and estimator, chained as uwb_driver and posture_estimator chain them."""

    def __init__(self, config, model, method, protocol):
        self.config, self.protocol = config, protocol
        self.decoder = LineDecoder(protocol)
        self.whole = self.decoder.format.whole_tag
        self.assembler = FrameAssembler(config, frame_period=1.0 / RATE)
        self.estimator = PostureEstimator(model, method, sigma=0.1)
        self.counts = Counter()
        self.first_error = None

    def decide(self, frame):
        """Update the estimator with an assembled frame; count the decision or what raised."""
        self.counts['frames_assembled'] += 1
        try:
            self.estimator.update(frame.ranges, tag_ranges=frame.tag_ranges, stamp=frame.stamp)
        except Exception:  # noqa: BLE001 - a soak counts what escapes, it does not stop
            self.counts['errors'] += 1
            self.first_error = self.first_error or traceback.format_exc()
            return
        self.counts['decisions'] += 1
        diagnostics = self.estimator.last_diagnostics
        self.counts['postures' if diagnostics['valid']
                    else f'rejected {diagnostics["status"]}'] += 1

    def send(self, index, ranges):
        """Send cycle ``index``: decide the frames due by its stamp, then read its lines."""
        stamp = 1.0 + index / RATE
        for frame in self.assembler.poll(stamp):
            self.decide(frame)
        for _, line in cycle_lines(self.config, ranges, self.protocol, index):
            self.counts['lines'] += 1
            records = self.decoder.decode(line)
            if records:
                for frame in self.assembler.add_line(records, stamp, None, self.whole):
                    self.decide(frame)

    def flush(self):
        """Decide the frames the assembler still holds."""
        for frame in self.assembler.poll(math.inf):
            self.decide(frame)

    def fields(self, frames):
        """Return the counts of ``frames`` cycles sent, from ``lines`` to ``frames_lost``."""
        counts = self.counts
        rejected = {key.split(' ', 1)[1]: value for key, value in sorted(counts.items())
                    if key.startswith('rejected ')}
        return {'lines': counts['lines'], 'frames_assembled': counts['frames_assembled'],
                'decisions': counts['decisions'], 'postures': counts['postures'],
                'rejected': rejected, 'errors': counts['errors'],
                'first_error': self.first_error, 'frames_lost': frames - counts['decisions']}


def soak_in_process(frames, method='chain', seed=0, protocol='json', progress=None):
    """
    Push ``frames`` ranging cycles through decoder, assembler and estimator in this process.

    Parameters
    ----------
    frames : int
        Ranging cycles sent (at least 2).
    method : str
        Estimator method.
    seed : int
        Seeds the working cycle and the noise.
    protocol : str
        Device line format.
    progress : callable(str), optional
        Told about progress every 10 %.

    Returns
    -------
    dict
        ``frames`` (cycles sent), ``lines``, ``frames_assembled``, ``decisions``,
        ``postures``, ``rejected`` (by status), ``errors`` (updates that raised; the first
        traceback in ``first_error``), ``frames_lost``, ``seconds``, ``frames_per_s``,
        ``rss_start_mb``, ``rss_warm_mb``, ``rss_end_mb``, ``rss_peak_mb``,
        ``rss_growth_pct`` (end against warm-up), decoder and assembler counts.

    """
    config = load_pump_config()
    model = config.model()
    rng = np.random.default_rng(seed)
    trajectory = working_cycle(model, CHUNK_SECONDS, RATE, rng=np.random.default_rng(seed))
    joints = trajectory.joints
    noise = RangeNoise(sigma=0.1, dropout=0.02)
    pipeline = _Pipeline(config, model, method, protocol)
    memory = _Memory(frames)
    step = max(1, frames // 100)
    start = time.perf_counter()
    for i in range(frames):
        ranges, _ = noise.apply(model.ranges(joints[_cycle_index(i, len(joints))]), rng)
        pipeline.send(i, ranges)
        done = i + 1
        memory.after(done)
        if done % step == 0:
            memory.sample()
        if progress is not None and done % max(1, frames // 10) == 0:
            progress(f'soak in-process: {done}/{frames} frames, '
                     f'{done / (time.perf_counter() - start):.0f} frames/s, '
                     f'RSS {rss_mb():.1f} MB')
    pipeline.flush()
    seconds = time.perf_counter() - start
    memory.finish()
    return {'method': method, 'protocol': protocol, 'frames': frames, **pipeline.fields(frames),
            'seconds': seconds, 'frames_per_s': frames / seconds, **memory.fields(),
            'decoder': dict(pipeline.decoder.counts),
            'assembler_dropped': dict(pipeline.assembler.dropped)}


def _diagnostic_values(message):
    """Return the key-values of posture_estimator's status in a DiagnosticArray, or None."""
    for status in message.status:
        if status.name.startswith('posture_estimator'):
            return {item.key: item.value for item in status.values}
    return None


class _Listener:
    """
    This process's node: the postures it receives, the estimator's latest diagnostics.

    Made, it has imported ROS (the in-process soak runs without); :meth:`start` starts it.
    """

    def __init__(self):
        from epp_ros.app import contract
        from epp_ros.nodes.messages import qos, RANGES_INPUT_QOS
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseArray
        import rclpy

        self.rclpy, self.contract, self._qos = rclpy, contract, qos
        self._types, self._keep_all = (PoseArray, DiagnosticArray), RANGES_INPUT_QOS
        self.node = None
        self.postures, self.latest = [], {}

    def start(self):
        """Initialise rclpy and subscribe to the postures and the diagnostics."""
        poses, diagnostics = self._types
        self.rclpy.init()
        self.node = self.rclpy.create_node('epp_bench_soak')
        self.node.create_subscription(
            poses, self.contract.POSTURE.name,
            lambda message: self.postures.append(time.perf_counter()),
            self._keep_all)                 # keep all: count every one
        self.node.create_subscription(diagnostics, self.contract.DIAGNOSTICS.name,
                                      self._on_diagnostics, self._qos(self.contract.DIAGNOSTICS))

    def _on_diagnostics(self, message):
        values = _diagnostic_values(message)
        if values is not None:
            self.latest.clear()
            self.latest.update(values)

    def spin(self, timeout):
        """Handle what has come, waiting up to ``timeout`` seconds."""
        self.rclpy.spin_once(self.node, timeout_sec=timeout)

    def spin_for(self, seconds):
        """Handle what comes for ``seconds``."""
        until = time.monotonic() + seconds
        while time.monotonic() < until:
            self.spin(0.05)

    def received(self):
        """Return the frames the estimator reports received."""
        return int(self.latest.get('frames received', 0))

    def wait_for(self, estimator):
        """Wait until the estimator subscribes and publishes, then let discovery settle."""
        ranges, posture = self.contract.RANGES.absolute, self.contract.POSTURE.absolute
        deadline = time.monotonic() + 30.0
        while (self.node.count_subscribers(ranges) < 1
               or self.node.count_publishers(posture) < 1):
            self.spin(0.05)
            if time.monotonic() > deadline or estimator.poll() is not None:
                raise RuntimeError('posture_estimator did not come up')
        for _ in range(20):
            self.spin(0.05)

    def counts(self):
        """Return the estimator's frame counts: received, published, unsolved, lost, ..."""
        return {key: int(self.latest.get(f'frames {key}', 0))
                for key in ('received', 'published', 'unsolved', 'errors', 'malformed',
                            'lost', 'before_first')}

    def accounted(self):
        """Return the frames the estimator has seen or counted lost (received + lost + ...)."""
        counts = self.counts()
        return counts['received'] + counts['lost'] + counts['before_first']

    def close(self):
        """Destroy the node and shut rclpy down."""
        self.node.destroy_node()
        self.rclpy.try_shutdown()


def _start_estimator(config_path, method, log):
    """Start a posture_estimator process with the pump description, its output into ``log``."""
    return subprocess.Popen(
        [sys.executable, '-m', 'epp_ros.nodes.estimator', '--ros-args', '--params-file',
         str(config_path), '-p', f'method:={method}', '-p', 'publish_markers:=false',
         '--log-level', 'warn'], stdout=log, stderr=subprocess.STDOUT)


def _start_player(bag, topic, speed=None):
    """Start ``epp_bag play`` of one topic of a bag: ``--fast``, or ``speed`` times real time."""
    timing = ['--fast'] if speed is None else ['--rate', str(speed), '--subscribers', '1']
    return subprocess.Popen(
        [sys.executable, '-m', 'epp_ros.cli.bag', 'play', str(bag), *timing,
         '--topics', topic], stdout=subprocess.DEVNULL)


def _follow(listener, player, memory, written, timeout, progress):
    """
    Spin while the player plays, reading the estimator's memory as it goes.

    Stops when the node has received all ``written`` frames and the player is done, when the
    player is done and nothing has come for :data:`QUIET` seconds, or after ``timeout``.
    """
    started = time.monotonic()
    deadline = started + timeout
    next_sample, next_report = started + 1.0, started + 30.0
    last_received, last_change = 0, started
    while time.monotonic() < deadline:
        listener.spin(0.01)
        now = time.monotonic()
        memory.after(len(listener.postures))
        if now > next_sample:
            memory.sample()
            next_sample = now + 1.0
        if progress and now > next_report:
            progress(f'soak live: {len(listener.postures)}/{written} postures received')
            next_report = now + 30.0
        if listener.received() != last_received:
            last_received, last_change = listener.received(), now
        if player.poll() is not None and (listener.received() >= written
                                          or now - last_change > QUIET):
            break                   # all in, or the player done and nothing more


def _stop(player, listener, estimator):
    """Stop the player (if still playing), this process's node and the estimator."""
    if player is not None and player.poll() is None:
        player.send_signal(signal.SIGINT)
        player.wait(10)
    listener.close()
    estimator.send_signal(signal.SIGINT)
    try:
        estimator.wait(10)
    except subprocess.TimeoutExpired:
        estimator.kill()
        estimator.wait()


def _tail(log, size=2000):
    """Return the last ``size`` characters of an open log file, and close it."""
    log.seek(0)
    text = log.read()[-size:]
    log.close()
    return text


def soak_live(frames, method='chain', seed=0, progress=None, timeout=None):
    """
    Play a ``frames``-frame bag with ``epp_bag play --fast`` into a posture_estimator.

    Returns
    -------
    dict
        ``frames`` (played), ``received``, ``published`` and ``unsolved`` (the node's
        ``/diagnostics`` counts), ``postures`` (received here), ``frames_lost`` (played -
        received by the node), ``seconds`` (first posture to last), ``frames_per_s``, the
        estimator process's ``rss_start_mb`` (before the first frame), ``rss_warm_mb``
        (after 1 % of the frames), ``rss_end_mb``, ``rss_peak_mb``, ``rss_growth_pct``,
        and ``complete`` (False when ``timeout`` ran out).

    """
    timeout = timeout if timeout is not None else 120.0 + frames / 50.0
    if progress:
        progress(f'soak live: synthesising a {frames}-frame bag')
    with _LiveRun(frames, method, seed) as run:
        memory = _Memory(frames, run.estimator.pid)
        _follow(run.listener, run.play(), memory, run.written, timeout, progress)
        memory.finish()
        complete = run.listener.received() >= run.written
        run.listener.spin_for(2.0)                          # late postures and a report
    counts = run.listener.counts()
    postures = run.listener.postures
    elapsed = postures[-1] - postures[0] if len(postures) > 1 else 0.0
    return {'method': method, 'frames': run.written, **counts, 'postures': len(postures),
            'frames_lost': run.written - counts['received'], 'complete': complete,
            'seconds': elapsed,
            'frames_per_s': (len(postures) - 1) / elapsed if elapsed > 0 else 0.0,
            **memory.fields(),
            'estimator_log_tail': run.log_tail if not complete or counts['errors'] else ''}


class _LiveRun:
    """
    A synthesised bag of ``frames`` frames and a posture_estimator process ready for it.

    ``with`` starts the estimator and this process's :class:`_Listener` and waits until
    they see each other; leaving stops the player (:meth:`play`), the listener and the
    estimator, and keeps the end of the estimator's log in ``log_tail``.
    """

    def __init__(self, frames, method, seed):
        self.frames, self.method, self.seed = frames, method, seed
        self.listener, self.player, self.estimator, self.log_tail = _Listener(), None, None, ''

    def __enter__(self):
        from epp_ros.app import bags
        self._folder = tempfile.TemporaryDirectory()
        folder = Path(self._folder.name)
        config_path = default_config_path()
        self.bag = folder / 'soak'
        self.written = bags.synthesize(self.bag, load_pump_config(config_path),
                                       duration=self.frames / RATE, rate=RATE, sigma=0.1,
                                       seed=self.seed)[bags.RANGES]
        self._log = open(folder / 'estimator.log', 'w+')
        os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 100)
        self.estimator = _start_estimator(config_path, self.method, self._log)
        self.listener.start()
        try:
            self.listener.wait_for(self.estimator)
        except BaseException:
            self.__exit__()
            raise
        return self

    def play(self, speed=None):
        """Start playing the bag's ranges (``--fast``, or ``speed`` times real time)."""
        self.player = _start_player(self.bag, self.listener.contract.RANGES.absolute, speed)
        return self.player

    def __exit__(self, *exc):
        _stop(self.player, self.listener, self.estimator)
        self.log_tail = _tail(self._log)
        self._folder.cleanup()


#: Seconds the lag phase plays before it stops the estimator, and after it lets it go on.
LAG_MARGIN = 5.0


def soak_lag(lag_seconds=30.0, rate=50.0, method='chain', seed=0, progress=None):
    """
    Play a bag in real time into a posture_estimator that is stopped for ``lag_seconds``.

    Frames go at ``rate`` Hz, as from uwb_driver; :data:`LAG_MARGIN` seconds into the
    stream the estimator is stopped (SIGSTOP), as a starved or stalled process, and after
    ``lag_seconds`` let go on (SIGCONT). The frames behind it the publisher could not keep
    are lost on the way; the estimator must count each from the frames' numbers.

    Returns
    -------
    dict
        ``frames`` (played), the node's ``received``, ``published``, ``unsolved``, ``lost``
        and ``before_first``, ``ignored`` (received, neither published nor unsolved), and
        ``accounted``: frames played = received + lost + before_first, exactly.

    """
    duration = lag_seconds + 2 * LAG_MARGIN
    with _LiveRun(int(round(duration * rate)), method, seed) as run:
        player = run.play(rate / RATE)
        _lag(run.listener, run.estimator, lag_seconds, progress)
        _settle(run.listener, player, run.written, timeout=120.0 + 2 * duration)
    counts, accounted = run.listener.counts(), run.written == run.listener.accounted()
    return {'method': method, 'lag_seconds': lag_seconds, 'rate_hz': rate,
            'frames': run.written, **counts,
            'ignored': counts['received'] - counts['published'] - counts['unsolved'],
            'accounted': accounted, 'estimator_log_tail': '' if accounted else run.log_tail}


def _lag(listener, estimator, seconds, progress):
    """Once frames flow, let LAG_MARGIN seconds pass, then stop the estimator ``seconds``."""
    deadline = time.monotonic() + 120.0
    while listener.received() == 0 and time.monotonic() < deadline:
        listener.spin(0.05)
    listener.spin_for(LAG_MARGIN)
    if progress:
        progress(f'soak lag: the estimator stopped for {seconds:g} s')
    os.kill(estimator.pid, signal.SIGSTOP)
    try:
        listener.spin_for(seconds)
    finally:
        os.kill(estimator.pid, signal.SIGCONT)


def _settle(listener, player, written, timeout):
    """Spin until the player is done and every frame is accounted for, or quiet, or timeout."""
    deadline = time.monotonic() + timeout
    last, changed = listener.accounted(), time.monotonic()
    while time.monotonic() < deadline:
        listener.spin(0.05)
        if listener.accounted() != last:
            last, changed = listener.accounted(), time.monotonic()
        if player.poll() is not None and (last >= written
                                          or time.monotonic() - changed > QUIET):
            break
    listener.spin_for(2.0)                                  # the latest report


@dataclass
class SoakReport:
    """
    The report of ``python3 dev.py bench soak`` (see :func:`run`).

    Attributes
    ----------
    method : str
    in_process : dict
        :func:`soak_in_process`.
    live : dict or None
        :func:`soak_live`; None when not run.
    lag : dict or None
        :func:`soak_lag`; None when not run.
    summary : dict
        The headline figures (see :func:`run`).

    """

    method: str
    in_process: dict
    live: dict | None
    summary: dict
    lag: dict | None = None
    suite: str = 'soak'


def run(frames=1_000_000, live_frames=100_000, method='chain', seed=0, progress=None,
        lag_seconds=30.0):
    """
    Run the soaks; the :class:`SoakReport`'s ``summary`` holds the headline figures.

    ``summary``: ``frames`` and ``frames_lost`` over both parts, ``rss_start_mb``,
    ``rss_warm_mb``, ``rss_end_mb`` and ``rss_growth_pct`` of the in-process part (this
    process), ``live_rss_*`` of the estimator process, ``frames_per_s`` and
    ``live_frames_per_s``, ``rss_ok`` (both ends within 10 % of warm-up), and of the lag
    phase (:func:`soak_lag`) ``lag_frames``, ``lag_lost`` and ``lag_accounted``.
    ``live_frames`` 0 skips the live part, ``lag_seconds`` 0 the lag phase.
    """
    in_process = soak_in_process(frames, method, seed, progress=progress)
    live = soak_live(live_frames, method, seed, progress) if live_frames else None
    parts = [in_process] + ([live] if live else [])
    summary = {'frames': sum(part['frames'] for part in parts),
               'frames_lost': sum(part['frames_lost'] for part in parts),
               'in_process_frames': in_process['frames'],
               'in_process_frames_lost': in_process['frames_lost'],
               'frames_per_s': in_process['frames_per_s'],
               **{key: in_process[key] for key in ('rss_start_mb', 'rss_warm_mb',
                                                   'rss_end_mb', 'rss_growth_pct')}}
    if live:
        summary.update({'live_frames': live['frames'], 'live_frames_lost': live['frames_lost'],
                        'live_frames_per_s': live['frames_per_s'],
                        **{f'live_{key}': live[key] for key in
                           ('rss_start_mb', 'rss_warm_mb', 'rss_end_mb', 'rss_growth_pct')}})
    summary['rss_ok'] = all(part['rss_growth_pct'] is not None and
                            abs(part['rss_growth_pct']) <= 100 * RSS_TOLERANCE for part in parts)
    lag = soak_lag(lag_seconds, method=method, seed=seed, progress=progress) \
        if lag_seconds else None
    if lag:
        summary.update({'lag_frames': lag['frames'], 'lag_lost': lag['lost'],
                        'lag_accounted': lag['accounted']})
    return SoakReport(method, in_process, live, summary, lag)
