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
``dev.py bench integrity``: whether the estimators publish wrong postures, and how they recover.

Streams on the simulated truck pump (a 10 Hz working cycle, range noise sigma = 0.1 m with
5 % of the links missing, every estimator told sigma = 0.1 m) with frames broken on
purpose: frames whose ranges are all, or one tag's, multiplied by independent U[0, 3)
factors; bursts of 3 to 10 frames of uniform 0-80 m garbage; absurd frames (all 0 m, all
0.1 m, all 20 m, random 0-80 m); frames with only two anchors, each from a cold start;
clean cycles on booms whose anchors are nearly collinear or nearly coincident; and frames
with one range 0.5-3 m short (a real link's outlier), each from a cold start. Per method:

- wrong and valid: frames reported valid while a joint of the returned posture is more
  than 1 m and more than 5 predicted standard deviations (``joint_std``) from the truth
  (target: none);
- recovery: seconds from a broken frame (the last of a burst) to the first valid frame
  within 1 m of the truth on every joint (target: <= 2 s);
- false rejections: the fraction of unbroken frames reported not valid, in the clean
  stream and in the streams with broken frames (target: <= 0.5 %);
- the time per frame.

No ROS: the estimators are called in-process.
"""
from collections import Counter
from dataclasses import asdict, dataclass, field
import time

from epp_ros.core import PostureEstimator
from epp_ros.core.estimation import WRONG_M
from epp_ros.core.model import BoomModel
from epp_ros.core.simulation import RangeNoise, truck_pump, working_cycle
import numpy as np

__all__ = ['CASES', 'Stream', 'FrameLog', 'CaseResult', 'MethodSummary', 'IntegrityReport',
           'build_streams', 'run_stream', 'score_case', 'summarize_method', 'run']

RATE = 10.0                         #: frames per second
SIGMA = 0.1                         #: range noise, and what the estimators are told, metres
DROPOUT = 0.05                      #: fraction of missing links
WRONG_METRES = WRONG_M              #: a joint this far off ...
WRONG_SIGMAS = 5.0                  #: ... and this many predicted sigmas is wrong
RECOVERY_TARGET_S = 2.0
FALSE_REJECTION_TARGET = 0.005
LEAD_S = 2.0                        #: clean seconds before the first broken frame
GAP_S = (3.0, 5.0)                  #: clean seconds between broken runs
BURST_FRAMES = (3, 10)              #: frames in a burst of garbage
GARBAGE_M = 80.0                    #: garbage ranges are uniform in [0, GARBAGE_M)
CORRUPTION = 3.0                    #: corrupted ranges are multiplied by U[0, CORRUPTION)
ABSURD = (('all 0 m', 0.0), ('all 0.1 m', 0.1), ('all 20 m', 20.0),
          ('random 0-80 m', None))
TWO_ANCHOR_RATE = 2.0               #: two-anchor (and one-short) frames per second of the cycle
SHORT = (0.5, 3.0)                  #: m, how much one range of a one-short frame falls short
DEGENERATE_SPREAD = 0.03            #: anchors within this many metres of a line or point
DETAIL_LIMIT = 20                   #: frames listed per method and case

#: The streams, in order; the broken ones score recovery, every one scores wrong-and-valid.
CASES = ('clean', 'corrupt_all', 'corrupt_tip', 'corrupt_one', 'garbage_bursts', 'absurd',
         'two_anchors', 'collinear', 'coincident', 'one_short')
BROKEN_CASES = ('corrupt_all', 'corrupt_tip', 'corrupt_one', 'garbage_bursts', 'absurd')
DESCRIPTIONS = {
    'clean': 'clean working cycle',
    'corrupt_all': 'a frame every 3-5 s with all ranges x U[0,3)',
    'corrupt_tip': "the same, the tip tag's ranges only",
    'corrupt_one': "the same, one random tag's ranges",
    'garbage_bursts': 'bursts of 3-10 frames of U[0,80) m every 3-5 s',
    'absurd': 'a frame every 3-5 s: all 0 m, 0.1 m, 20 m or U[0,80) m',
    'two_anchors': 'two random anchors only, cold start each frame',
    'collinear': f'anchors within {DEGENERATE_SPREAD * 100:.0f} cm of a line, clean cycle',
    'coincident': f'anchors within {DEGENERATE_SPREAD * 100:.0f} cm of a point, clean cycle',
    'one_short': f'one random range {SHORT[0]}-{SHORT[1]:.0f} m short (an outlier), '
                 'cold start each frame',
}


@dataclass
class Stream:
    """
    Frames of one case, with the truth and where they were broken.

    Attributes
    ----------
    case : str
        One of :data:`CASES`.
    model : BoomModel
        The boom the frames were simulated on (and the estimator is given).
    ranges : ndarray, shape (T, p, m)
        Tag-anchor ranges, metres, NaN where missing.
    stamps : ndarray, shape (T,)
        Frame times, seconds.
    truths : ndarray, shape (T, p, 3)
        True joint positions, metres.
    events : list of (int, int)
        First and last frame of each broken run.
    labels : list of str
        What broke each run.
    scored : ndarray of bool, shape (T,)
        Unbroken frames that count for false rejections.
    cold : bool
        Whether the estimator forgets its warm start before every frame.

    """

    case: str
    model: BoomModel
    ranges: np.ndarray
    stamps: np.ndarray
    truths: np.ndarray
    events: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    scored: np.ndarray = None
    cold: bool = False


def case_rng(seed, case, purpose=0):
    """Return the seeded Generator of one case (and purpose: noise, breakage, anchors)."""
    return np.random.default_rng([seed, CASES.index(case), purpose])


def noisy_ranges(model, joints, rng):
    """Ranges of true joints (..., p, 3) with the suite's noise and dropouts."""
    return RangeNoise(sigma=SIGMA, dropout=DROPOUT).apply(model.ranges(joints), rng)[0]


def cycle_stream(model, seconds, seed, case):
    """Build a working cycle at :data:`RATE` with noisy ranges; every frame scored, none broken."""
    trajectory = working_cycle(model, seconds, RATE, rng=np.random.default_rng(seed))
    ranges = noisy_ranges(model, trajectory.joints, case_rng(seed, case))
    return Stream(case, model, ranges, trajectory.times, trajectory.joints,
                  scored=np.ones(len(trajectory.times), bool))


def broken_runs(frames, rng, length=(1, 1)):
    """
    (first, last) frames of broken runs: after :data:`LEAD_S`, :data:`GAP_S` apart.

    Parameters
    ----------
    frames : int
        Length of the stream.
    rng : numpy.random.Generator
        Draws the runs' lengths and the gaps between them.
    length : (int, int)
        Fewest and most frames in a run.

    """
    runs, start = [], int(LEAD_S * RATE)
    gap = (int(GAP_S[0] * RATE), int(GAP_S[1] * RATE))
    while True:
        count = int(rng.integers(length[0], length[1] + 1))
        if start + count > frames:
            return runs
        runs.append((start, start + count - 1))
        start += count + int(rng.integers(gap[0], gap[1] + 1))


def _break(stream, runs, labels):
    """Record broken runs: they are events, and their frames are not scored."""
    stream.events, stream.labels = runs, labels
    for first, last in runs:
        stream.scored[first:last + 1] = False
    return stream


def corrupted_stream(seconds, seed, tags='all'):
    """
    Single frames with ranges multiplied by independent U[0, 3) factors.

    ``tags``: ``'all'`` (every range), ``'tip'`` (the tip tag's row) or ``'one'`` (a
    random tag's row, drawn per frame).
    """
    case = f'corrupt_{tags}'
    stream = cycle_stream(truck_pump(), seconds, seed, case)
    rng = case_rng(seed, case, 1)
    p = stream.model.n_sections
    runs = broken_runs(len(stream.stamps), rng)
    labels = []
    for first, _ in runs:
        row = {'all': slice(None), 'tip': p - 1}.get(tags)
        if row is None:
            row = int(rng.integers(p))
        rows = stream.ranges[first, row]
        stream.ranges[first, row] = rows * rng.uniform(0.0, CORRUPTION, rows.shape)
        labels.append('all tags' if tags == 'all' else f'tag {row + 1}')
    return _break(stream, runs, labels)


def garbage_stream(seconds, seed):
    """Bursts of 3 to 10 frames of uniform 0-80 m ranges."""
    stream = cycle_stream(truck_pump(), seconds, seed, 'garbage_bursts')
    rng = case_rng(seed, 'garbage_bursts', 1)
    runs = broken_runs(len(stream.stamps), rng, BURST_FRAMES)
    for first, last in runs:
        shape = stream.ranges[first:last + 1].shape
        stream.ranges[first:last + 1] = rng.uniform(0.0, GARBAGE_M, shape)
    return _break(stream, runs, [f'{last - first + 1} frames' for first, last in runs])


def absurd_stream(seconds, seed):
    """Single absurd frames, in turn all 0 m, all 0.1 m, all 20 m and random 0-80 m."""
    stream = cycle_stream(truck_pump(), seconds, seed, 'absurd')
    rng = case_rng(seed, 'absurd', 1)
    runs = broken_runs(len(stream.stamps), rng)
    labels = []
    for index, (first, _) in enumerate(runs):
        label, value = ABSURD[index % len(ABSURD)]
        shape = stream.ranges[first].shape
        stream.ranges[first] = (rng.uniform(0.0, GARBAGE_M, shape) if value is None
                                else np.full(shape, value))
        labels.append(label)
    return _break(stream, runs, labels)


def cold_stream(seconds, seed, case, spoil):
    """
    Frames of the cycle at :data:`TWO_ANCHOR_RATE`, each spoilt and solved cold; none scored.

    ``spoil(frame, model, rng)`` changes one frame's noisy ranges (p, m) in place.
    """
    model = truck_pump()
    trajectory = working_cycle(model, seconds, RATE, rng=np.random.default_rng(seed))
    pick = slice(None, None, max(int(round(RATE / TWO_ANCHOR_RATE)), 1))
    rng = case_rng(seed, case)
    joints = trajectory.joints[pick]
    ranges = noisy_ranges(model, joints, rng)
    for frame in ranges:
        spoil(frame, model, rng)
    return Stream(case, model, ranges, trajectory.times[pick], joints,
                  scored=np.zeros(len(joints), bool), cold=True)


def two_anchor_stream(seconds, seed):
    """Frames of the cycle at :data:`TWO_ANCHOR_RATE` keeping two random anchors, cold."""
    def keep_two(frame, model, rng):
        keep = rng.choice(model.n_anchors, 2, replace=False)
        frame[:, np.setdiff1d(np.arange(model.n_anchors), keep)] = np.nan
    return cold_stream(seconds, seed, 'two_anchors', keep_two)


def one_short_stream(seconds, seed):
    """
    Frames of the cycle at :data:`TWO_ANCHOR_RATE`, one random range of each :data:`SHORT`, cold.

    A real link's outlier (up to 3.3 m recorded, either sign); short, it is no NLOS
    excess. No frame scored for rejections: without that range a joint may be ambiguous.
    """
    def one_short(frame, model, rng):
        frame[rng.integers(model.n_sections), rng.integers(model.n_anchors)] -= \
            rng.uniform(*SHORT)
    return cold_stream(seconds, seed, 'one_short', one_short)


def degenerate_model(shape, rng, spread=DEGENERATE_SPREAD):
    """
    Build the truck pump's boom with its anchors nearly on a line or nearly at one point.

    Built directly (the config loader refuses such anchors), yet just past what
    ``BoomModel`` refuses: anchors 1 cm apart and 1 cm off a line.

    Parameters
    ----------
    shape : str
        ``'collinear'``: ``spread`` metres off a 10 m line under the boom, each in a random
        direction; ``'coincident'``: on a sphere of radius ``spread`` round one point on the
        chassis, evenly spread and randomly turned.
    rng : numpy.random.Generator
        Draws the anchors' directions off the line or the sphere's turn.
    spread : float
        Metres.

    """
    reference = truck_pump()
    m = reference.n_anchors
    if shape == 'collinear':
        angle = rng.uniform(0.0, 2.0 * np.pi, m)
        offsets = np.column_stack([np.zeros(m), np.cos(angle), np.sin(angle)])
        centres = np.column_stack([np.linspace(-5.0, 5.0, m), np.zeros(m), np.full(m, 0.5)])
    else:
        height = np.linspace(1.0 - 1.0 / m, 1.0 / m - 1.0, m)      # a Fibonacci sphere
        azimuth = np.pi * (3.0 - np.sqrt(5.0)) * np.arange(m)
        ring = np.sqrt(1.0 - height ** 2)
        turn = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        offsets = np.column_stack([ring * np.cos(azimuth), ring * np.sin(azimuth),
                                   height]) @ turn
        centres = np.tile([3.0, 2.0, 0.5], (m, 1))
    return BoomModel(reference.arm_lengths, reference.base, centres + spread * offsets)


def degenerate_stream(seconds, seed, shape):
    """Make a clean working cycle on a :func:`degenerate_model`; no frame scored for rejections."""
    model = degenerate_model(shape, case_rng(seed, shape, 1))
    stream = cycle_stream(model, seconds, seed, shape)
    stream.scored[:] = False
    return stream


def build_streams(seconds, seed, cases=CASES):
    """Build the streams of ``cases`` (names in :data:`CASES`), ``seconds`` long each."""
    builders = {
        'clean': lambda: cycle_stream(truck_pump(), seconds, seed, 'clean'),
        'corrupt_all': lambda: corrupted_stream(seconds, seed, 'all'),
        'corrupt_tip': lambda: corrupted_stream(seconds, seed, 'tip'),
        'corrupt_one': lambda: corrupted_stream(seconds, seed, 'one'),
        'garbage_bursts': lambda: garbage_stream(seconds, seed),
        'absurd': lambda: absurd_stream(seconds, seed),
        'two_anchors': lambda: two_anchor_stream(seconds, seed),
        'collinear': lambda: degenerate_stream(seconds, seed, 'collinear'),
        'coincident': lambda: degenerate_stream(seconds, seed, 'coincident'),
        'one_short': lambda: one_short_stream(seconds, seed),
    }
    return [builders[case]() for case in cases]


@dataclass
class FrameLog:
    """
    What an estimator reported on each frame of a stream.

    Attributes
    ----------
    valid : ndarray of bool, shape (T,)
    errors : ndarray, shape (T, p)
        Distance of each returned joint from the truth, metres.
    joint_std : ndarray, shape (T, p)
        Predicted per-joint standard deviation, metres; NaN when not given.
    status, message : list of str
    reacquired, cold_start : ndarray of bool, shape (T,)
    seconds : ndarray, shape (T,)
        Wall time of each ``update``.

    """

    valid: np.ndarray
    errors: np.ndarray
    joint_std: np.ndarray
    status: list
    message: list
    reacquired: np.ndarray
    cold_start: np.ndarray
    seconds: np.ndarray


def run_stream(stream, method, options):
    """
    Feed a stream to a new ``PostureEstimator``; the :class:`FrameLog`.

    ``options``: keyword options of the estimator (``sigma`` defaults to :data:`SIGMA`).
    """
    estimator = PostureEstimator(stream.model, method, **{'sigma': SIGMA, **options})
    p = stream.model.n_sections
    rows = []
    for ranges, stamp, truth in zip(stream.ranges, stream.stamps, stream.truths):
        if stream.cold:
            estimator.reset()
        start = time.perf_counter()
        posture = estimator.update(ranges, stamp=float(stamp))
        seconds = time.perf_counter() - start
        diagnostics = estimator.last_diagnostics
        joint_std = diagnostics.get('joint_std')
        rows.append((bool(diagnostics['valid']), np.linalg.norm(posture - truth, axis=1),
                     np.full(p, np.nan) if joint_std is None else np.asarray(joint_std, float),
                     diagnostics['status'], diagnostics.get('message', ''),
                     bool(diagnostics.get('reacquired')), bool(diagnostics.get('cold_start')),
                     seconds))
    columns = list(zip(*rows))
    return FrameLog(np.array(columns[0]), np.array(columns[1]), np.array(columns[2]),
                    list(columns[3]), list(columns[4]), np.array(columns[5]),
                    np.array(columns[6]), np.array(columns[7]))


def wrong_and_valid(log):
    """
    Boolean (T, p): valid frames' joints > 1 m and > 5 predicted sigmas off.

    A valid frame without a ``joint_std`` is judged on the distance alone.
    """
    std = np.where(np.isfinite(log.joint_std), log.joint_std, 0.0)
    return (log.valid[:, None] & (log.errors > WRONG_METRES)
            & (log.errors > WRONG_SIGMAS * std))


def recoveries(stream, log):
    """
    Seconds from each broken run's last frame to the first valid frame within 1 m.

    The search stops at the next broken run: None when not recovered by then.
    """
    good = log.valid & np.all(log.errors <= WRONG_METRES, axis=1)
    ends = [first for first, _ in stream.events[1:]] + [len(stream.stamps)]
    times = []
    for (_, last), end in zip(stream.events, ends):
        hits = np.flatnonzero(good[last + 1:end])
        times.append(float(stream.stamps[last + 1 + hits[0]] - stream.stamps[last])
                     if hits.size else None)
    return times


@dataclass
class CaseResult:
    """
    One method on one stream.

    Attributes
    ----------
    method, case : str
    frames : int
    valid : int
        Frames reported valid.
    wrong_valid : int
        Of those, wrong (see :func:`wrong_and_valid`).
    wrong_indices : list of int
        Which frames.
    scored : int
        Unbroken frames that count for false rejections.
    rejected : int
        Of those, reported not valid.
    rejected_statuses : dict
        Of those, frames per reported status.
    events : int
        Broken runs.
    recoveries_s : list of float or None
        Per broken run (see :func:`recoveries`).
    statuses : dict
        Frames per reported status.
    seconds : list of float
        Wall time per frame.

    """

    method: str
    case: str
    frames: int
    valid: int
    wrong_valid: int
    wrong_indices: list
    scored: int
    rejected: int
    rejected_statuses: dict
    events: int
    recoveries_s: list
    statuses: dict
    seconds: list


def _frame_detail(stream, log, index, **extra):
    """Return a frame's index, stamp, status and message, for the report's lists."""
    return {'case': stream.case, 'frame': int(index), 'stamp_s': float(stream.stamps[index]),
            'status': log.status[index], 'message': log.message[index],
            'reacquired': bool(log.reacquired[index]),
            'cold_start': bool(log.cold_start[index]), **extra}


def score_case(stream, method, log):
    """
    Return the :class:`CaseResult` of a log, and details of the frames that miss a target.

    Returns
    -------
    result : CaseResult
    details : dict
        ``wrong_frames`` (wrong-and-valid frames: their wrong ``joints``, 1-based, with
        ``errors_m`` and ``joint_std_m``), ``slow_recoveries``
        (runs not recovered within :data:`RECOVERY_TARGET_S`) and ``rejections``
        (scored frames reported not valid), at most :data:`DETAIL_LIMIT` each.

    """
    wrong = wrong_and_valid(log)
    rejected = stream.scored & ~log.valid
    times = recoveries(stream, log)
    result = CaseResult(method, stream.case, len(log.valid), int(log.valid.sum()),
                        int(wrong.any(axis=1).sum()),
                        np.flatnonzero(wrong.any(axis=1)).tolist(), int(stream.scored.sum()),
                        int(rejected.sum()),
                        dict(Counter(np.array(log.status)[rejected].tolist())),
                        len(stream.events), times,
                        dict(Counter(log.status)), log.seconds.tolist())
    wrong_frames = []
    for index in np.flatnonzero(wrong.any(axis=1))[:DETAIL_LIMIT]:
        joints = np.flatnonzero(wrong[index])
        wrong_frames.append(_frame_detail(
            stream, log, index, method=method, joints=(joints + 1).tolist(),
            errors_m=log.errors[index, joints].tolist(),
            joint_std_m=log.joint_std[index, joints].tolist()))
    slow = []
    for (first, last), label, seconds in zip(stream.events, stream.labels, times):
        if seconds is None or seconds > RECOVERY_TARGET_S:
            after = slice(last + 1, last + 1 + int(RECOVERY_TARGET_S * RATE))
            slow.append(_frame_detail(
                stream, log, last, method=method, first=int(first), label=label,
                recovery_s=seconds, statuses_after=dict(Counter(log.status[after])),
                messages_after=sorted(set(log.message[after]))[:5]))
    rejections = [_frame_detail(stream, log, index, method=method)
                  for index in np.flatnonzero(rejected)[:DETAIL_LIMIT]]
    return result, {'wrong_frames': wrong_frames, 'slow_recoveries': slow[:DETAIL_LIMIT],
                    'rejections': rejections}


@dataclass
class MethodSummary:
    """
    One method over every stream: the suite's targets.

    Attributes
    ----------
    method : str
    frames : int
    wrong_valid : int
        Wrong-and-valid frames, every stream (target 0).
    events : int
        Broken runs, in the :data:`BROKEN_CASES` streams.
    unrecovered : int
        Of those, not recovered before the next.
    recovery_worst_s, recovery_median_s : float or None
        Over the recovered runs (target: worst <= 2 s).
    clean_rejected, clean_scored : int
        Frames of the clean stream reported not valid, of all.
    broken_rejected, broken_scored : int
        Unbroken frames of the broken streams reported not valid, of all.
    ms_median, ms_p99 : float
        Per-frame time, every stream.

    """

    method: str
    frames: int
    wrong_valid: int
    events: int
    unrecovered: int
    recovery_worst_s: float
    recovery_median_s: float
    clean_rejected: int
    clean_scored: int
    broken_rejected: int
    broken_scored: int
    ms_median: float
    ms_p99: float

    @property
    def false_rejection_clean(self):
        """Fraction of the clean stream's frames reported not valid."""
        return self.clean_rejected / max(self.clean_scored, 1)

    @property
    def false_rejection_broken(self):
        """Fraction of the broken streams' unbroken frames reported not valid."""
        return self.broken_rejected / max(self.broken_scored, 1)


def _rejected_of_scored(results):
    """Return the rejected and the scored frames of some :class:`CaseResult`, summed."""
    return sum(r.rejected for r in results), sum(r.scored for r in results)


def _recovery_figures(broken):
    """
    Return the recovery figures of the broken streams' :class:`CaseResult` list.

    Returns
    -------
    events, unrecovered : int
        Broken runs, and of those the ones not recovered before the next.
    worst, median : float or None
        Over the recovered runs, seconds; None when none recovered.

    """
    times = [t for r in broken for t in r.recoveries_s]
    recovered = [t for t in times if t is not None]
    worst, median = (max(recovered), float(np.median(recovered))) if recovered else (None, None)
    return len(times), len(times) - len(recovered), worst, median


def summarize_method(method, results):
    """Return the :class:`MethodSummary` of a method's :class:`CaseResult` list."""
    broken = [r for r in results if r.case in BROKEN_CASES]
    clean = [r for r in results if r.case == 'clean']
    seconds = np.concatenate([r.seconds for r in results])
    return MethodSummary(
        method, sum(r.frames for r in results), sum(r.wrong_valid for r in results),
        *_recovery_figures(broken), *_rejected_of_scored(clean), *_rejected_of_scored(broken),
        1e3 * float(np.median(seconds)), 1e3 * float(np.percentile(seconds, 99)))


@dataclass
class IntegrityReport:
    """
    The report of ``python3 dev.py bench integrity`` (see :func:`run`).

    Attributes
    ----------
    seconds : float
    seed : int
    sigma_m, dropout : float
    cases : dict
        Name -> description.
    rows : list of dict
        :class:`MethodSummary` per method, with ``false_rejection_clean`` and
        ``false_rejection_broken``.
    case_rows : list of dict
        :class:`CaseResult` per method and case, without the frame times.
    wrong_frames, slow_recoveries, rejections : list of dict
        See :func:`score_case`.

    """

    seconds: float
    seed: int
    sigma_m: float
    dropout: float
    cases: dict
    rows: list = field(default_factory=list)
    case_rows: list = field(default_factory=list)
    wrong_frames: list = field(default_factory=list)
    slow_recoveries: list = field(default_factory=list)
    rejections: list = field(default_factory=list)
    suite: str = 'integrity'


def run(methods, seconds=60.0, seed=0, options=None, cases=CASES):
    """
    Run the integrity suite; return its :class:`IntegrityReport`.

    Parameters
    ----------
    methods : list of str
        Range methods (``PostureEstimator`` names).
    seconds : float
        Length of each stream.
    seed : int
        Seeds every stream (each case and purpose its own generator, see :func:`case_rng`).
    options : dict, optional
        Estimator options for every method (``sigma`` defaults to :data:`SIGMA`).
    cases : sequence of str
        Of :data:`CASES`.

    """
    streams = build_streams(seconds, seed, cases)
    report = IntegrityReport(seconds, seed, SIGMA, DROPOUT,
                             {case: DESCRIPTIONS[case] for case in cases})
    for method in methods:
        results = []
        for stream in streams:
            result, details = score_case(stream, method, run_stream(stream, method,
                                                                    options or {}))
            results.append(result)
            for key, items in details.items():
                getattr(report, key).extend(items)
        summary = summarize_method(method, results)
        report.rows.append(dict(asdict(summary),
                                false_rejection_clean=summary.false_rejection_clean,
                                false_rejection_broken=summary.false_rejection_broken))
        report.case_rows += [{key: value for key, value in asdict(result).items()
                              if key != 'seconds'} for result in results]
    return report
