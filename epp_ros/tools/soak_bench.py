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
epp_bench soak: a long stream through the parser, the assembler and the estimator.

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

from epp_ros.config import default_config_path, load_pump_config
from epp_ros.core import PostureEstimator
from epp_ros.core.simulate import RangeNoise, working_cycle
from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.emulation import cycle_lines
from epp_ros.uwb.frames import FrameAssembler
import numpy as np

__all__ = ['rss_mb', 'soak_in_process', 'soak_live', 'SoakReport', 'run', 'markdown',
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
    decoder = LineDecoder(protocol)
    whole = decoder.format.whole_tag
    assembler = FrameAssembler(config, frame_period=1.0 / RATE)
    estimator = PostureEstimator(model, method, sigma=0.1)
    counts = Counter()
    first_error = []

    def decide(frame):
        counts['frames_assembled'] += 1
        try:
            estimator.update(frame.ranges, tag_ranges=frame.tag_ranges, stamp=frame.stamp)
        except Exception:  # noqa: BLE001 - a soak counts what escapes, it does not stop
            counts['errors'] += 1
            if not first_error:
                first_error.append(traceback.format_exc())
            return
        counts['decisions'] += 1
        diagnostics = estimator.last_diagnostics
        counts['postures' if diagnostics['valid'] else f'rejected {diagnostics["status"]}'] += 1

    warm_at = max(1, int(round(frames * WARMUP)))
    step = max(1, frames // 100)
    rss_start = rss_warm = rss_mb()
    peak = rss_start or 0.0
    start = time.perf_counter()
    for i in range(frames):
        stamp = 1.0 + i / RATE
        ranges, _ = noise.apply(model.ranges(joints[_cycle_index(i, len(joints))]), rng)
        for frame in assembler.poll(stamp):
            decide(frame)
        for _, line in cycle_lines(config, ranges, protocol, i):
            counts['lines'] += 1
            records = decoder.decode(line)
            if records:
                for frame in assembler.add_line(records, stamp, None, whole):
                    decide(frame)
        done = i + 1
        if done == warm_at:
            rss_warm = rss_mb()
        if done % step == 0:
            peak = max(peak, rss_mb() or 0.0)
        if progress is not None and done % max(1, frames // 10) == 0:
            progress(f'soak in-process: {done}/{frames} frames, '
                     f'{done / (time.perf_counter() - start):.0f} frames/s, '
                     f'RSS {rss_mb():.1f} MB')
    for frame in assembler.poll(math.inf):
        decide(frame)
    seconds = time.perf_counter() - start
    rss_end = rss_mb()
    rejected = {key.split(' ', 1)[1]: value for key, value in sorted(counts.items())
                if key.startswith('rejected ')}
    return {'method': method, 'protocol': protocol, 'frames': frames,
            'lines': counts['lines'], 'frames_assembled': counts['frames_assembled'],
            'decisions': counts['decisions'], 'postures': counts['postures'],
            'rejected': rejected, 'errors': counts['errors'],
            'first_error': first_error[0] if first_error else None,
            'frames_lost': frames - counts['decisions'],
            'seconds': seconds, 'frames_per_s': frames / seconds,
            'rss_start_mb': rss_start, 'rss_warm_mb': rss_warm, 'rss_end_mb': rss_end,
            'rss_peak_mb': max(peak, rss_end or 0.0),
            'rss_growth_pct': _growth(rss_warm, rss_end),
            'decoder': dict(decoder.counts), 'assembler_dropped': dict(assembler.dropped)}


def _diagnostic_values(message):
    """Return the key-values of posture_estimator's status in a DiagnosticArray, or None."""
    for status in message.status:
        if status.name.startswith('posture_estimator'):
            return {item.key: item.value for item in status.values}
    return None


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
    from epp_ros import bags, contract
    from epp_ros.nodes.common import qos, RANGES_INPUT_QOS
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray
    import rclpy

    config_path = default_config_path()
    config = load_pump_config(config_path)
    timeout = timeout if timeout is not None else 120.0 + frames / 50.0
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / 'soak'
        if progress:
            progress(f'soak live: synthesising a {frames}-frame bag')
        written = bags.synthesize(bag, config, duration=frames / RATE, rate=RATE, sigma=0.1,
                                  seed=seed)[bags.RANGES]
        log = open(Path(folder) / 'estimator.log', 'w+')
        os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 100)
        estimator = subprocess.Popen(
            [sys.executable, '-m', 'epp_ros.nodes.estimator', '--ros-args', '--params-file',
             str(config_path), '-p', f'method:={method}', '-p', 'publish_markers:=false',
             '--log-level', 'warn'], stdout=log, stderr=subprocess.STDOUT)
        rclpy.init()
        node = rclpy.create_node('epp_bench_soak')
        postures, latest = [], {}
        node.create_subscription(PoseArray, contract.POSTURE.name,
                                 lambda message: postures.append(time.perf_counter()),
                                 RANGES_INPUT_QOS)      # keep all: count every one

        def on_diagnostics(message):
            values = _diagnostic_values(message)
            if values is not None:
                latest.clear()
                latest.update(values)
        node.create_subscription(DiagnosticArray, contract.DIAGNOSTICS.name, on_diagnostics,
                                 qos(contract.DIAGNOSTICS))
        player = None
        try:
            deadline = time.monotonic() + 30.0
            while (node.count_subscribers(contract.RANGES.absolute) < 1
                   or node.count_publishers(contract.POSTURE.absolute) < 1):
                rclpy.spin_once(node, timeout_sec=0.05)
                if time.monotonic() > deadline or estimator.poll() is not None:
                    raise RuntimeError('posture_estimator did not come up')
            for _ in range(20):                             # let discovery settle
                rclpy.spin_once(node, timeout_sec=0.05)
            rss_start = rss_warm = rss_mb(estimator.pid)
            peak = rss_start or 0.0
            warm_at = max(1, int(round(frames * WARMUP)))
            player = subprocess.Popen(
                [sys.executable, '-m', 'epp_ros.tools.bag', 'play', str(bag), '--fast',
                 '--topics', contract.RANGES.absolute], stdout=subprocess.DEVNULL)
            started = time.monotonic()
            deadline = started + timeout
            warm_taken, next_sample, next_report = False, started + 1.0, started + 30.0
            last_received, last_change = 0, started

            def received():
                return int(latest.get('frames received', 0))
            while time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.01)
                now = time.monotonic()
                if not warm_taken and len(postures) >= warm_at:
                    rss_warm, warm_taken = rss_mb(estimator.pid), True
                if now > next_sample:
                    peak = max(peak, rss_mb(estimator.pid) or 0.0)
                    next_sample = now + 1.0
                if progress and now > next_report:
                    progress(f'soak live: {len(postures)}/{written} postures received')
                    next_report = now + 30.0
                if received() != last_received:
                    last_received, last_change = received(), now
                if player.poll() is not None and (received() >= written
                                                  or now - last_change > QUIET):
                    break                   # all in, or the player done and nothing more
            rss_end = rss_mb(estimator.pid)
            complete = received() >= written
            settle = time.monotonic() + 2.0                   # late postures and a report
            while time.monotonic() < settle:
                rclpy.spin_once(node, timeout_sec=0.05)
        finally:
            if player is not None and player.poll() is None:
                player.send_signal(signal.SIGINT)
                player.wait(10)
            node.destroy_node()
            rclpy.try_shutdown()
            estimator.send_signal(signal.SIGINT)
            try:
                estimator.wait(10)
            except subprocess.TimeoutExpired:
                estimator.kill()
                estimator.wait()
            log.seek(0)
            log_tail = log.read()[-2000:]
            log.close()
    counts = {key: int(latest.get(f'frames {key}', 0))
              for key in ('received', 'published', 'unsolved', 'errors', 'malformed')}
    elapsed = postures[-1] - postures[0] if len(postures) > 1 else 0.0
    return {'method': method, 'frames': written, **counts, 'postures': len(postures),
            'frames_lost': written - counts['received'], 'complete': complete,
            'seconds': elapsed,
            'frames_per_s': (len(postures) - 1) / elapsed if elapsed > 0 else 0.0,
            'rss_start_mb': rss_start, 'rss_warm_mb': rss_warm, 'rss_end_mb': rss_end,
            'rss_peak_mb': max(peak, rss_end or 0.0),
            'rss_growth_pct': _growth(rss_warm, rss_end),
            'estimator_log_tail': log_tail if not complete or counts['errors'] else ''}


@dataclass
class SoakReport:
    """
    The report of ``epp_bench soak`` (see :func:`run`).

    Attributes
    ----------
    method : str
    in_process : dict
        :func:`soak_in_process`.
    live : dict or None
        :func:`soak_live`; None when not run.
    summary : dict
        The headline figures (see :func:`run`).

    """

    method: str
    in_process: dict
    live: dict | None
    summary: dict
    suite: str = 'soak'


def run(frames=1_000_000, live_frames=100_000, method='chain', seed=0, progress=None):
    """
    Run both soaks; the :class:`SoakReport`'s ``summary`` holds the headline figures.

    ``summary``: ``frames`` and ``frames_lost`` over both parts, ``rss_start_mb``,
    ``rss_warm_mb``, ``rss_end_mb`` and ``rss_growth_pct`` of the in-process part (this
    process), ``live_rss_*`` of the estimator process, ``frames_per_s`` and
    ``live_frames_per_s``, ``rss_ok`` (both ends within 10 % of warm-up). ``live_frames``
    0 skips the live part.
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
    return SoakReport(method, in_process, live, summary)


def _mb(value):
    return '-' if value is None else f'{value:.1f}'


def _percent(value):
    return '-' if value is None else f'{value:+.1f} %'


def markdown(report):
    """Format a :func:`run` report as a markdown table."""
    lines = [f'### Soak: {report.method}, parser + assembler + estimator in-process, '
             'and epp_bag play --fast through the live node', '',
             '| part | frames | decisions (postures / rejected) | frames lost | frames/s | '
             'RSS start [MB] | after warm-up | end | peak | end vs warm-up |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for name, part in (('in-process', report.in_process), ('live node', report.live)):
        if part is None:
            continue
        if name == 'in-process':
            rejected = sum(part['rejected'].values())
            decided = f'{part["decisions"]} ({part["postures"]} / {rejected})'
        else:
            decided = (f'{part["received"]} received ({part["published"]} / '
                       f'{part["unsolved"]}), {part["postures"]} postures here')
        lines.append(f'| {name} | {part["frames"]} | {decided} | {part["frames_lost"]} | '
                     f'{part["frames_per_s"]:.0f} | {_mb(part["rss_start_mb"])} | '
                     f'{_mb(part["rss_warm_mb"])} | {_mb(part["rss_end_mb"])} | '
                     f'{_mb(part["rss_peak_mb"])} | {_percent(part["rss_growth_pct"])} |')
    in_process = report.in_process
    lines += ['', 'Frames lost: cycles sent that reached no decision (in-process), frames '
              'played that the node did not receive (live). Rejections are decisions.']
    if in_process['rejected']:
        lines.append(f'In-process rejections by reason: {in_process["rejected"]}.')
    if in_process['errors']:
        lines += [f'{in_process["errors"]} updates raised; the first:', '```',
                  in_process['first_error'].rstrip(), '```']
    live = report.live
    if live and not live['complete']:
        lines.append("The live part did not complete in time; the node's log ends:")
        lines += ['```', live['estimator_log_tail'].rstrip(), '```']
    verdict = 'met' if report.summary['frames_lost'] == 0 and report.summary['rss_ok'] \
        else 'NOT met'
    lines.append(f'Target (nothing lost, RSS at the end within {RSS_TOLERANCE:.0%} of warm-up): '
                 f'{verdict}.')
    return '\n'.join(lines)
