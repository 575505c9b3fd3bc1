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
The accuracy and speed experiments of the benchmarks: what is run, on what, with which seeds.

Each experiment returns a typed report (a dataclass; JSON by ``dataclasses.asdict``).
``python3 dev.py bench`` (:mod:`benchmarks.bench`) and the paper's reproduction
(:mod:`benchmarks.paper`) are front ends over them; :mod:`benchmarks.reports`
formats the reports. Per frame the error is the paper's RMSE over the joints
(:func:`~epp_ros.core.estimation.frame_rmse`); over frames a report gives its root mean square
(``rmse_m``) and its mean (``mean_rmse_m``, what the paper printed and plotted).
"""
from dataclasses import asdict, dataclass, field
import itertools
from pathlib import Path
import tempfile
import time
from typing import NamedTuple

from epp_ros.core import BoomModel, METHODS, PostureEstimator
from epp_ros.core.estimation import frame_rmse, IntegrityLimits, pooled_rmse, wrong_frames
from epp_ros.core.estimation.methods import angles_from_joints, CEPP, ChainMethod
from epp_ros.core.model import (crlb, fit_slew, from_plane, Measurements, Residuals, SensorNoise,
                                to_plane)
from epp_ros.core.simulation import (AngleNoise, observe, random_posture, RangeNoise, truck_pump,
                                     working_cycle, XIE3DIM, xie3dim)
from epp_ros.core.solvers import cold_start_guess
import numpy as np

#: The method the paper published under each of our names, where ours departs from it, and
#: the options its runs here need: the paper's CEPP (H = 1, no searches) with its plane
#: fitted to each frame, since the paper never says how a cold frame finds its plane.
AS_PUBLISHED = {'cepp': ('cepp_paper', {'predict_slew': True})}
#: Additive range noise of the xie3dim experiment, metres (the authors').
XIE3DIM_SIGMA = XIE3DIM['published_sigma_m']
#: The authors' names of their xie3dim figures, as printed here.
PUBLISHED_NAMES = {'EMBED_CEPP': 'EMBED/CEPP', 'SR-LS_3D': 'SR-LS 3-D', 'SDP_3D': 'SDP 3-D',
                   'improved_variant': 'improved variant'}
#: The authors' xie3dim figure of a method run as published (the others have none).
PUBLISHED_METHODS = {'srls': 'SR-LS_3D', 'sdp': 'SDP_3D'}
#: Table 1 of the paper: absolute arm-length error per segment (as printed, its segment 1
#: may be the tip: it numbers points from the tip) and CPU seconds (MATLAB).
PAPER_TABLE1 = {'sdp': ([1.639, 1.623, 1.554, 1.540, 1.681], 0.286),
                'srls': ([2.215, 4.964, 5.780, 4.743, 5.024], 0.519),
                'epp1': ([1.630, 1.629, 1.554, 1.548, 1.692], 0.041),
                'epp2': ([0.057, 0.014, 0.015, 0.016, 0.017], 0.047)}
#: Table 3 (NLOS): mean RMSE metres and CPU seconds; the paper's "CEPP2" is our cepp.
PAPER_TABLE3 = {'sdp': (4.503, 0.312), 'srls': (5.464, 0.539), 'tpsm': (4.765, 0.019),
                'epp2': (4.249, 0.048), 'cepp': (2.533, 0.063)}
ETAS = (0.01, 0.02, 0.05, 0.1, 0.2)
SIGMAS = (0.1, 0.2, 0.5, 1.0, 2.0)
TABLE1_ETA = 0.1
SWEEP_METHODS = ['sdp', 'srls', 'epp1', 'epp2', 'cepp', 'chain']
NLOS_METHODS = ['sdp', 'srls', 'tpsm', 'epp2', 'cepp', 'chain']
#: The chain's NLOS prior where the simulated noise is Gaussian.
GAUSSIAN = 0.0
#: Distance at some joint beyond which a fit is another posture, not noise about one, m.
OTHER_POSTURE = 0.5
#: The chain's targets: section lengths per number of sections, anchors, missing links.
TARGET_LENGTHS = {4: (10.0, 8.0, 9.0, 9.0), 5: (9.0, 7.0, 7.0, 9.0, 9.0),
                  6: (8.0, 7.0, 6.0, 7.0, 6.0, 6.0)}
TARGET_ANCHORS = (4, 5, 6)
TARGET_MISSING = (0.0, 0.15)


# -- reports --------------------------------------------------------------------------------
@dataclass
class Published:
    """A figure the authors published on xie3dim: over ``trials``, the mean and RMS of RMSE."""

    key: str                    #: their name (``simulate.XIE3DIM``)
    name: str                   #: as printed here
    mean_rmse_m: float          #: the mean of the per-trial RMSE: what they printed
    rms_rmse_m: float           #: its root mean square, from their code
    trials: int


@dataclass
class Summary:
    """One method over a set of frames."""

    rmse_m: float               #: root mean square of the per-frame RMSE
    mean_rmse_m: float          #: mean of the per-frame RMSE
    arm_length_error_m: list    #: mean absolute error of each section's length
    ms_median: float            #: time per frame
    ms_p99: float
    #: What a user gets: the RMSE over the frames published as valid, the fraction
    #: published, and of those how many more than ``metrics.WRONG_M`` off, and how many
    #: with a predicted RMSE under a third of their error (None: not judged, as the
    #: paper's variants)
    valid_rmse_m: float | None = None
    published_fraction: float | None = None
    wrong_valid: int | None = None
    confidently_wrong: int | None = None


@dataclass
class MethodRow(Summary):
    """A method's (or variant's) row of a table, with the bound and a published figure."""

    method: str = ''
    crlb_m: float = float('nan')
    published: Published | None = None


@dataclass
class Xie3dimReport:
    """The authors' geometry, a cold start per trial (``python3 dev.py bench xie3dim``)."""

    trials: int
    sigma_m: float
    crlb_m: float
    rows: list                  #: :class:`MethodRow`
    #: Largest |slew - true slew| of the variants solved in the true plane, radians.
    truth_plane_slew_error_rad: float | None = None
    ambiguity: list = field(default_factory=list)   #: :class:`AmbiguityRow`
    suite: str = 'xie3dim'


@dataclass
class AmbiguityRow:
    """One method at one ``ambiguity_odds`` on the xie3dim frames: what it publishes."""

    method: str
    odds: float
    published_fraction: float
    valid_ratio: float          #: RMSE over the frames published / the CRLB
    wrong_valid: int            #: published while more than 1 m off
    confidently_wrong: int      #: of those, with a predicted RMSE under a third of the error


@dataclass
class TrackingReport:
    """The truck pump on a working cycle, warm-started (``python3 dev.py bench tracking``)."""

    frames: int
    sigma_m: float
    dropout: float
    crlb_m: float               #: of the ranges
    rows: list                  #: :class:`MethodRow`
    fused_crlb_m: float | None = None   #: of everything ``chain+angles`` fuses
    suite: str = 'tracking'


@dataclass
class LatencyRow:
    """One method's latency through the node at 10 and 100 Hz, and its sustained rate."""

    method: str
    p50_ms_10hz: float
    p99_ms_10hz: float
    lost_10hz: int
    p50_ms_100hz: float
    p99_ms_100hz: float
    lost_100hz: int
    sustained_hz: float
    parameter_p99_ms: float = float('nan')     #: set_parameters response while frames flow
    parameter_max_ms: float = float('nan')
    parameter_frames_p99_ms: float = float('nan')   #: the frames' latency meanwhile
    parameter_lost: int = 0                     #: frames and calls unanswered meanwhile


@dataclass
class LatencyReport:
    """posture_estimator fed over DDS from another process (``python3 dev.py bench latency``)."""

    seconds: float
    rows: list                  #: :class:`LatencyRow`
    suite: str = 'latency'


@dataclass
class ControllerRow:
    """One method's node on a shared core: latency percentiles (ms), frames unanswered."""

    method: str
    frames: int
    p50_ms: float
    p90_ms: float
    p99_ms: float
    max_ms: float
    unanswered: int
    refused: int                #: the node's count of frames it solved but did not publish
    received: int               #: the node's count of frames received (warm-up included)


@dataclass
class ControllerReport:
    """The node on one shared core at 10 Hz (``python3 dev.py bench controller``)."""

    seconds: float
    rows: list                  #: :class:`ControllerRow`
    suite: str = 'controller'


@dataclass
class BagsRow:
    """One method on a bag: offline evaluation and fast replay through the node."""

    method: str
    eval_fps: float
    play_fps: float
    lost: int


@dataclass
class BagsReport:
    """A synthesised bag evaluated and replayed (``python3 dev.py bench bags``)."""

    frames: int
    rows: list                  #: :class:`BagsRow`
    suite: str = 'bags'


@dataclass
class SweepRow:
    """One noise level of a sweep: range * (1 + eta N) + sigma N."""

    eta: float
    sigma: float
    crlb_m: float
    methods: dict               #: method -> :class:`Summary`


@dataclass
class SweepReport:
    """RMSE against the noise on the paper's manipulator; ``kind`` is what varies."""

    kind: str                   #: 'eta' or 'sigma'
    runs: int
    rows: list                  #: :class:`SweepRow`


@dataclass
class NlosReport:
    """The paper's Table 3: NLOS ranges on the truck pump, random postures."""

    runs: int
    sigma_m: float
    nlos_fraction: float
    gamma_m: float
    los_crlb_m: float
    methods: dict               #: method -> :class:`Summary`


@dataclass
class TargetRow:
    """The chain on one truck pump: RMSE against the bound, search misses, other postures."""

    sections: int
    anchors: int
    missing: float
    runs: int
    rmse_m: float
    local_fit_rmse_m: float
    search_misses: int
    crlb_m: float
    other_posture_frames: int
    rmse_same_posture_m: float
    ms_median: float


@dataclass
class TargetsReport:
    """The chain's targets on 4-6 sections, 4-6 anchors, 0 or 15 % missing."""

    sigma_m: float
    rows: list                  #: :class:`TargetRow`


@dataclass
class PaperParts:
    """The parts of the paper's reproduction."""

    sweep_eta: SweepReport
    sweep_sigma: SweepReport
    nlos: NlosReport
    xie3dim: Xie3dimReport
    tracking: TrackingReport
    targets: TargetsReport


@dataclass
class PaperReport:
    """The paper's reproduction (``python3 dev.py bench paper``); ``out``: where it was written."""

    runs: int
    seed: int
    reports: PaperParts
    out: str = ''


@dataclass(frozen=True)
class Variant:
    """
    A method as an experiment runs it.

    Attributes
    ----------
    label : str
        Its row's name.
    method : str
        A ``PostureEstimator`` method.
    options : dict
        Its options beyond the experiment's.
    fused : bool
        Given every sensor it uses, not the tag-anchor ranges alone.
    truth_plane : bool
        CEPP solving in the true posture's plane (:class:`TruthPlaneCEPP`).
    published : str or None
        The authors' xie3dim figure it is the counterpart of (``simulate.XIE3DIM``).

    """

    label: str
    method: str
    options: dict = field(default_factory=dict)
    fused: bool = False
    truth_plane: bool = False
    published: str | None = None


TOH = {'stress_refinement': True}
#: The xie3dim part of the paper's reproduction: the authors' EMBED refines EPP1 and CEPP
#: (in the true plane) by Toh's post-processing; their 'improved_variant' has no counterpart.
PAPER_XIE3DIM = (
    Variant('epp1', 'epp1'),
    Variant("epp1 + Toh (EMBED's EPP1)", 'epp1', TOH),
    Variant('epp2', 'epp2'),
    Variant("cepp (the paper's; plane from the frame, our cold start)", 'cepp'),
    Variant("cepp, plane from the truth (the authors' set-up)", 'cepp', truth_plane=True,
            published='EMBED_CEPP'),
    Variant("cepp + Toh, plane from the truth (the authors' EMBED/CEPP)", 'cepp', TOH,
            truth_plane=True, published='EMBED_CEPP'),
    Variant('chain', 'chain'),
    Variant('srls', 'srls', published='SR-LS_3D'),
    Variant('sdp', 'sdp', published='SDP_3D'),
)


def published_figure(key):
    """Return the authors' :class:`Published` xie3dim figure named ``key``, or None."""
    if key is None:
        return None
    return Published(key, PUBLISHED_NAMES[key], XIE3DIM['published_mean_rmse_m'][key],
                     XIE3DIM['published_rms_rmse_m'][key], XIE3DIM['published_trials'])


# -- running a method on frames -------------------------------------------------------------
def method_inputs(method, frame, fused=False):
    """
    Return what a method is given of a simulated frame (a dict of ``update`` keywords).

    Methods that use ranges get the tag-anchor ranges alone, unless ``fused``; the others
    (TPSM) their angle sensors.
    """
    if not isinstance(frame, dict):
        frame = {'ranges': frame}
    inputs = METHODS[method].inputs
    if 'ranges' in inputs and not fused:
        inputs = ('ranges',)
    return {'ranges': frame['ranges'] if 'ranges' in inputs else
            np.full_like(frame['ranges'], np.nan),
            **{key: value for key, value in frame.items() if key in inputs and key != 'ranges'}}


def method_estimate(estimator, frame):
    """
    Return the method's estimate of a frame, whether the integrity checks pass it or not.

    The accuracy suites score the methods themselves; ``update`` returns only postures
    that may be published (``python3 dev.py bench integrity`` scores that).
    """
    held = estimator.update(**frame)
    return estimator.last_diagnostics.get('estimate', held)


def run_frames(estimator, frames, truths, cold=False, fused=False):
    """
    Feed frames to an estimator; per-frame RMSE, arm-length error and wall time.

    Parameters
    ----------
    estimator : PostureEstimator or TruthPlaneCEPP
        Scored on its ``last_diagnostics['estimate']`` of each frame.
    frames : sequence
        Range arrays (p, m) or dicts of ``update`` keywords, passed through
        :func:`method_inputs`.
    truths : sequence of ndarray, shape (p, 3)
        The true joints of each frame.
    cold : bool
        Forget the warm start before each frame.
    fused : bool
        See :func:`method_inputs`.

    Returns
    -------
    rmses : ndarray, shape (T,)
    length_errors : ndarray, shape (T, p)
    times : ndarray, shape (T,)
        Seconds.
    valid : ndarray, shape (T,)
        1.0 where the frame was published as valid, 0.0 where not, NaN where the
        estimator does not judge its frames.
    predicted : ndarray, shape (T,)
        The predicted RMSE of each frame, metres (NaN: none).

    """
    rmses, length_errors, times, valid, predicted = [], [], [], [], []
    for frame, truth in zip(frames, truths):
        frame = method_inputs(estimator.method, frame, fused)
        if cold:
            estimator.reset()
        start = time.perf_counter()
        estimate = method_estimate(estimator, frame)
        times.append(time.perf_counter() - start)
        rmses.append(float(frame_rmse(estimate, truth)))
        diagnostics = estimator.last_diagnostics
        length_errors.append(diagnostics['arm_length_error'])
        valid.append(float(diagnostics['valid']) if 'valid' in diagnostics else np.nan)
        predicted.append(float(diagnostics.get('predicted_rmse', np.nan)))
    return (np.array(rmses), np.array(length_errors), np.array(times), np.array(valid),
            np.array(predicted))


def summarize(rmses, lengths, times, valid, predicted):
    """Return the :class:`Summary` of :func:`run_frames`' arrays."""
    judged = {}
    if len(valid) and np.isfinite(valid).all():
        published = valid.astype(bool)
        wrong, confident = wrong_frames(rmses ** 2, published, predicted)
        judged = {'valid_rmse_m': pooled_rmse(rmses[published]),
                  'published_fraction': float(published.mean()), 'wrong_valid': wrong,
                  'confidently_wrong': confident}
    return Summary(rmse_m=pooled_rmse(rmses), mean_rmse_m=float(np.mean(rmses)),
                   arm_length_error_m=lengths.mean(axis=0).tolist(),
                   ms_median=1e3 * float(np.median(times)),
                   ms_p99=1e3 * float(np.percentile(times, 99)), **judged)


def method_options(method, options, sigma):
    """Return the user's options, plus the suite's range noise (every method is told it)."""
    return options if 'sigma' in options else dict(options, sigma=sigma)


def published(model, method, options):
    """
    Return the estimator of a paper reproduction: the method as published, told the truth.

    The noise is what the suite simulates, so nothing is learned.
    """
    name, own = AS_PUBLISHED.get(method, (method, {}))
    return PostureEstimator(model, name, **{**own, 'learn_noise': False, **options})


class TruthPlaneCEPP:
    """
    The authors' CEPP set-up: the paper's CEPP solving in the true posture's plane.

    Shaped as a ``PostureEstimator`` for :func:`run_frames` (``method``, ``reset``,
    ``update``, ``last_diagnostics``), the method object called directly: every frame
    starts from the SR-LS cold-start guess projected into the true vertical plane, which
    the paper's CEPP (``predict_slew=False``) then solves in. The slew each frame was
    solved at is kept in ``slews``.

    Parameters
    ----------
    model : BoomModel
    truth : ndarray, shape (p, 3)
        The true joints; their plane is used.
    **options
        More options of :class:`~epp_ros.core.estimation.methods.CEPP` (``sigma``,
        ``stress_refinement``).

    """

    method = 'cepp'

    def __init__(self, model, truth, **options):
        self.model = model
        self.slew = fit_slew(truth, model.base)
        self.solver = CEPP(model, **options)
        self.slews = []
        self.last_diagnostics = {}

    def reset(self):
        """Start cold: nothing is carried from one frame to the next anyway."""

    def update(self, ranges, **_):
        """Solve a frame from the cold-start guess in the true plane; return the joints."""
        base = self.model.base
        guess = cold_start_guess(self.model, ranges)
        if guess is None:           # no tag located: a straight boom in the plane
            guess = self.model.forward_kinematics(self.slew, np.zeros(self.model.n_sections))
        prior = from_plane(to_plane(guess, base, self.slew), base, self.slew)
        # Warm: the paper's CEPP keeps the prior's plane, here the true one.
        joints, info = self.solver.solve(Measurements.ranges_only(ranges), prior, warm=True)
        self.slews.append(info['slew'])
        lengths = self.model.section_lengths(joints)
        self.last_diagnostics = {'estimate': joints, 'slew': info['slew'],
                                 'arm_length_error': np.abs(lengths - self.model.arm_lengths)}
        return joints

    def slew_error(self):
        """Return the largest |solved slew - true slew| so far, radians (0 if none)."""
        offsets = np.asarray(self.slews) - self.slew
        return float(np.max(np.abs(np.angle(np.exp(1j * offsets))), initial=0.0))


# -- xie3dim --------------------------------------------------------------------------------
def xie3dim_frames(model, truth, trials, seed, sigma=XIE3DIM_SIGMA):
    """Return ``trials`` range frames of the posture ``truth`` with additive noise ``sigma``."""
    rng = np.random.default_rng(seed)
    noise = RangeNoise(sigma=sigma)
    return [noise.apply(model.ranges(truth), rng)[0] for _ in range(trials)]


def variant_estimator(model, truth, variant, options, sigma):
    """
    Return the estimator of a :class:`Variant`: the method as published, told ``sigma``.

    ``options``: the user's, for every method (not for the truth-plane variants, which
    take the method's own options only).
    """
    if variant.truth_plane:
        return TruthPlaneCEPP(model, truth, sigma=sigma, **variant.options)
    return published(model, variant.method, method_options(
        variant.method, {**variant.options, **options}, sigma))


def xie3dim_experiment(variants, trials, seed, options=None):
    """
    Run the authors' geometry at sigma = 1 m, each trial from a cold start.

    Parameters
    ----------
    variants : sequence of Variant
        One row each, in this order.
    trials : int
        Frames, each its own draw of the noise.
    seed : int
        Seeds the noise; every variant gets the same frames.
    options : dict, optional
        Estimator options for every variant solved by a ``PostureEstimator``.

    Returns
    -------
    Xie3dimReport

    """
    model, truth = xie3dim()
    frames = xie3dim_frames(model, truth, trials, seed)
    bound = crlb(model, *angles_from_joints(model, truth), XIE3DIM_SIGMA).rmse
    rows, planes = [], []
    for variant in variants:
        estimator = variant_estimator(model, truth, variant, options or {}, XIE3DIM_SIGMA)
        summary = summarize(*run_frames(estimator, frames, [truth] * trials, cold=True))
        rows.append(MethodRow(**asdict(summary), method=variant.label, crlb_m=bound,
                              published=published_figure(variant.published)))
        if isinstance(estimator, TruthPlaneCEPP):
            planes.append(estimator.slew_error())
    return Xie3dimReport(trials, XIE3DIM_SIGMA, bound, rows,
                         max(planes) if planes else None)


#: The ambiguity odds of the xie3dim suite's sweep (``IntegrityLimits.ambiguity_odds``,
#: by default 1000).
AMBIGUITY_ODDS = (10.0, 30.0, 100.0, 1000.0)


def ambiguity_sweep(methods, trials, seed):
    """
    Return what each method publishes on the xie3dim frames at each of :data:`AMBIGUITY_ODDS`.

    Each method with its defaults (``cepp``: the field CEPP), told sigma, a cold start per
    frame: how many frames the data decide at each odds, and what that costs in frames
    published while wrong.
    """
    model, truth = xie3dim()
    frames = xie3dim_frames(model, truth, trials, seed)
    bound = crlb(model, *angles_from_joints(model, truth), XIE3DIM_SIGMA).rmse
    rows = []
    for method, odds in itertools.product(methods, AMBIGUITY_ODDS):
        estimator = PostureEstimator(model, method, sigma=XIE3DIM_SIGMA, learn_noise=False,
                                     integrity=IntegrityLimits(ambiguity_odds=odds))
        summary = summarize(*run_frames(estimator, frames, [truth] * trials, cold=True))
        rows.append(AmbiguityRow(method, odds, summary.published_fraction,
                                 summary.valid_rmse_m / bound, summary.wrong_valid,
                                 summary.confidently_wrong))
    return rows


def xie3dim_suite(methods, trials, seed, options):
    """
    Run ``dev.py bench xie3dim``: each method as published (see :func:`xie3dim_experiment`).

    The chain and CEPP asked for also run at each ambiguity odds (:func:`ambiguity_sweep`).
    """
    variants = [Variant(method, method, published=PUBLISHED_METHODS.get(method))
                for method in methods]
    report = xie3dim_experiment(variants, trials, seed, options)
    report.ambiguity = ambiguity_sweep([m for m in methods if m in ('chain', 'cepp')], trials,
                                       seed)
    return report


def paper_xie3dim(runs, seed, methods):
    """Run the paper's xie3dim variants (:data:`PAPER_XIE3DIM`) of ``methods``."""
    return xie3dim_experiment([v for v in PAPER_XIE3DIM if v.method in methods], runs, seed)


# -- tracking -------------------------------------------------------------------------------
def _tracking_bounds(model, trajectory, frames, fused_noise):
    """Return the pooled bound of the ranges alone and of everything fused."""
    alone, fused = [], []
    for slew, pitches, frame in zip(trajectory.slew, trajectory.pitches, frames):
        alone.append(crlb(model, slew, pitches, 0.1, np.isfinite(frame['ranges'])).rmse)
        fused.append(crlb(model, slew, pitches, fused_noise,
                          Measurements.clean(model, **frame)[0]).rmse)
    return pooled_rmse(alone), pooled_rmse(fused)


def tracking_suite(methods, seconds, seed, options):
    """
    Run a working cycle at 10 Hz, warm-started; with tpsm asked for, also chain+angles.

    The inclinometers and the slew encoder are simulated as TPSM's (``AngleNoise``); the
    range methods get the ranges alone, tpsm the angles alone, and ``chain+angles`` both,
    scored against the bound of everything it fuses (the uniform slew error taken as
    Gaussian of the same variance).
    """
    model = truck_pump()
    trajectory = working_cycle(model, seconds, 10.0, rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    noise, angle_noise = RangeNoise(sigma=0.1, dropout=0.05), AngleNoise()
    frames = [observe(model, slew, pitches, rng, noise, angle_noise=angle_noise)[0]
              for slew, pitches in zip(trajectory.slew, trajectory.pitches)]
    angles = {'pitch_sigma': angle_noise.pitch_sigma, 'slew_sigma': angle_noise.slew_sigma}
    variants = [Variant(method, method) for method in methods]
    if 'chain' in methods and 'tpsm' in methods:
        variants.append(Variant('chain+angles', 'chain', angles, fused=True))
    bounds = _tracking_bounds(model, trajectory, frames, SensorNoise(0.1, 0.1, **angles))
    rows = []
    for variant in variants:
        estimator = PostureEstimator(model, variant.method, **method_options(
            variant.method, dict(options, **variant.options), 0.1))
        summary = summarize(*run_frames(estimator, frames, trajectory.joints,
                                        fused=variant.fused))
        rows.append(MethodRow(**asdict(summary), method=variant.label,
                              crlb_m=bounds[variant.fused]))
    return TrackingReport(len(frames), 0.1, 0.05, bounds[0], rows,
                          bounds[1] if any(v.fused for v in variants) else None)


# -- the node and bags ----------------------------------------------------------------------
def _latency_row(method, frames, seconds):
    """Measure one method's latency at 10 and 100 Hz and its sustained rate."""
    from benchmarks.node_bench import measure_latency, parameter_response, sustained_rate
    values = {}
    for rate in (10.0, 100.0):
        latencies, lost = measure_latency(method, frames, rate, seconds)
        values[f'p50_ms_{rate:g}hz'] = 1e3 * float(np.median(latencies))
        values[f'p99_ms_{rate:g}hz'] = 1e3 * float(np.percentile(latencies, 99))
        values[f'lost_{rate:g}hz'] = lost
    responses, latencies, lost, unanswered = parameter_response(method, frames,
                                                                max(seconds, 2.0))
    values.update(parameter_p99_ms=1e3 * float(np.percentile(responses, 99)),
                  parameter_max_ms=1e3 * float(np.max(responses)),
                  parameter_frames_p99_ms=1e3 * float(np.percentile(latencies, 99)),
                  parameter_lost=lost + unanswered)
    return LatencyRow(method, **values, sustained_hz=sustained_rate(method, frames))


def latency_suite(methods, seconds, seed):
    """Latency and throughput of the estimator node, measured from another process."""
    model = truck_pump()
    trajectory = working_cycle(model, 600.0, 10.0, rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    frames = [RangeNoise(sigma=0.1).apply(model.ranges(j), rng)[0]
              for j in trajectory.joints[:2000]]
    return LatencyReport(seconds, [_latency_row(method, frames, seconds) for method in methods])


def controller_suite(methods, seconds, seed):
    """Each method's node pinned to a core a busy process shares, fed at 10 Hz for ``seconds``."""
    from benchmarks.node_bench import pinned_latency
    model = truck_pump()
    # Frames are picked by wall time since node_bench's import: longer than every run,
    # they never wrap round to a jump in the motion.
    duration = len(methods) * (seconds + 60.0) + 60.0
    trajectory = working_cycle(model, duration, 10.0, rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    frames = [RangeNoise(sigma=0.1).apply(model.ranges(j), rng)[0] for j in trajectory.joints]
    rows = []
    for method in methods:
        latencies, lost, counts = pinned_latency(method, frames, 10.0, seconds)
        p50, p90, p99 = (1e3 * float(np.percentile(latencies, q)) for q in (50, 90, 99))
        rows.append(ControllerRow(method, latencies.size + lost, p50, p90, p99,
                                  1e3 * float(latencies.max()), lost,
                                  *((counts.get('unsolved', 0), counts['received'])
                                    if 'received' in counts else (-1, -1))))
    return ControllerReport(seconds, rows)


def _bags_row(method, bag, config, frames):
    """Evaluate a bag offline and replay it through the node with one method."""
    from epp_ros.app import bags
    from benchmarks.node_bench import replay_rate
    start = time.perf_counter()
    bags.evaluate(bag, config, method)
    eval_rate = frames / (time.perf_counter() - start)
    play_rate, lost = replay_rate(method, bag, frames)
    return BagsRow(method, eval_rate, play_rate, lost)


def bags_suite(methods, seed):
    """Offline evaluation and fast replay through the node, frames per second."""
    from epp_ros.app import bags
    from epp_ros.app.config import load_pump_config
    config = load_pump_config()
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / 'cycle'
        frames = bags.synthesize(bag, config, duration=60.0, sigma=0.1, seed=seed)[bags.RANGES]
        rows = [_bags_row(method, bag, config, frames) for method in methods]
    return BagsReport(frames, rows)


# -- the paper's noise sweeps and NLOS table ------------------------------------------------
def paper_manipulator():
    """
    Return the p = 5, 9/7/7/9/9 m manipulator on the authors' anchors, in their posture.

    Returns
    -------
    model : BoomModel
    slew : float
    pitches : ndarray, shape (5,)

    """
    authors, joints = xie3dim()
    model = BoomModel([9.0, 7.0, 7.0, 9.0, 9.0], authors.base, authors.anchors)
    slew, pitches = angles_from_joints(authors, joints)
    return model, slew, pitches


def _estimators(model, methods, options):
    """Return each method's estimator as published, with ``options[method]`` if any."""
    return {m: published(model, m, options.get(m, {})) for m in methods}


def _sweep_row(model, angles, kind, level, runs, methods, seed):
    """Return the :class:`SweepRow` of one noise level: every method from cold starts."""
    joints = model.forward_kinematics(*angles)
    truth = model.ranges(joints)
    rng = np.random.default_rng([seed, int(level * 1e6)])
    noise = RangeNoise(eta=level) if kind == 'eta' else RangeNoise(sigma=level)
    frames = [noise.apply(truth, rng)[0] for _ in range(runs)]
    # The chain is told the noise model, Gaussian here, as every method is told sigma.
    chain = {'sigma': 1e-3, 'eta': level} if kind == 'eta' else {'sigma': level}
    chain['nlos_fraction'] = GAUSSIAN
    summaries = {method: summarize(*run_frames(estimator, frames, [joints] * runs, cold=True))
                 for method, estimator in _estimators(model, methods, {'chain': chain}).items()}
    eta, sigma = (level, 0.0) if kind == 'eta' else (0.0, level)
    bound = crlb(model, *angles, level * truth if kind == 'eta' else level).rmse
    return SweepRow(eta, sigma, bound, summaries)


def noise_sweep(kind, levels, runs, methods, seed):
    """
    RMSE of each method at each noise level, cold start per run, and the CRLB.

    ``kind`` is ``'eta'`` (range * (1 + eta N)) or ``'sigma'`` (range + sigma N).
    """
    model, slew, pitches = paper_manipulator()
    return SweepReport(kind, runs, [_sweep_row(model, (slew, pitches), kind, level, runs,
                                               methods, seed) for level in levels])


def nlos_table(runs, methods, seed, fraction=0.2, gamma=2.0, sigma=0.2):
    """Table 3: NLOS ranges on the truck pump, random postures, cold start per run."""
    model = truck_pump()
    rng = np.random.default_rng([seed, 3])
    noise = RangeNoise(sigma=sigma, nlos_fraction=fraction, nlos_gamma=gamma)
    postures, frames, bounds = [], [], []
    for _ in range(runs):
        slew, pitches, joints = random_posture(model, rng)
        frame, nlos = observe(model, slew, pitches, rng, noise, angle_noise=AngleNoise())
        postures.append(joints)
        frames.append(frame)
        bounds.append(crlb(model, slew, pitches, sigma, ~nlos).rmse)
    # The chain is told the simulated error model, as every method is told sigma.
    chain = {'sigma': sigma, 'nlos_fraction': fraction, 'nlos_gamma': gamma}
    estimators = _estimators(model, methods, {'chain': chain})
    summaries = {method: summarize(*run_frames(estimator, frames, postures, cold=True))
                 for method, estimator in estimators.items()}
    return NlosReport(runs, sigma, fraction, gamma, pooled_rmse(bounds), summaries)


# -- the chain's targets --------------------------------------------------------------------
class TargetFrame(NamedTuple):
    """One frame of a target case: the chain's cold start against the fit from the truth."""

    squared: float              #: mean squared joint error of the estimate, m^2
    local: float                #: of the fit from the true angles
    bound: float                #: the frame's CRLB (RMSE), m
    seconds: float              #: the estimator's time
    miss: bool                  #: the fit from the truth ends lower than the cold start
    other: bool                 #: the estimate is another posture than that fit


def target_frame(model, estimator, reference, rng, sigma, missing):
    """
    Simulate one random posture, solve it cold and fit it from the truth.

    Returns None when the measured links do not determine the posture (infinite bound).
    ``reference``: the chain method that fits from the true angles.
    """
    slew, pitches, joints = random_posture(model, rng)
    frame, _ = observe(model, slew, pitches, rng, RangeNoise(sigma=sigma, dropout=missing))
    bound = crlb(model, slew, pitches, sigma, np.isfinite(frame['ranges'])).rmse
    if not np.isfinite(bound):
        return None
    estimator.reset()
    start = time.perf_counter()
    estimate = method_estimate(estimator, frame)
    seconds = time.perf_counter() - start
    residuals = Residuals(model, Measurements.ranges_only(frame['ranges']), reference.noise)
    near = reference.fit(np.r_[slew, pitches], residuals)
    found = np.r_[estimator.last_diagnostics['slew'], estimator.last_diagnostics['pitches']]
    near_joints = model.forward_kinematics(near.psi[0], near.psi[1:])
    return TargetFrame(float(np.mean(np.sum((estimate - joints) ** 2, axis=1))),
                       float(np.mean(np.sum((near_joints - joints) ** 2, axis=1))), bound,
                       seconds, bool(near.cost < reference.cost(found, residuals) - 1e-3),
                       bool(np.linalg.norm(estimate - near_joints, axis=1).max()
                            > OTHER_POSTURE))


def target_case(sections, anchors, missing, runs, seed, sigma):
    """Return the :class:`TargetRow` of one truck pump (see :func:`target_cases`)."""
    model = truck_pump(TARGET_LENGTHS[sections], n_anchors=anchors)
    rng = np.random.default_rng([seed, sections, anchors, int(missing * 100)])
    estimator = PostureEstimator(model, 'chain', sigma=sigma, nlos_fraction=GAUSSIAN)
    reference = ChainMethod(model, sigma=sigma, nlos_fraction=GAUSSIAN)
    frames = [target_frame(model, estimator, reference, rng, sigma, missing)
              for _ in range(runs)]
    frames = [frame for frame in frames if frame is not None]
    squared = np.array([frame.squared for frame in frames])
    other = np.array([frame.other for frame in frames], bool)
    return TargetRow(sections, anchors, missing, len(frames),
                     rmse_m=float(np.sqrt(np.mean(squared))),
                     local_fit_rmse_m=float(np.sqrt(np.mean([f.local for f in frames]))),
                     search_misses=sum(frame.miss for frame in frames),
                     crlb_m=pooled_rmse([frame.bound for frame in frames]),
                     other_posture_frames=int(other.sum()),
                     rmse_same_posture_m=pooled_rmse(np.sqrt(squared[~other])),
                     ms_median=1e3 * float(np.median([f.seconds for f in frames])))


def target_cases(runs, seed, sigma=0.1):
    """
    Chain RMSE / CRLB on truck pumps of 4-6 sections and 4-6 anchors, 0 or 15 % missing.

    Each frame is also fitted from the true angles: that local fit is what the (local) CRLB
    describes, and a cold start that ends with a higher cost than it (by more than 0.001 in
    the loss, half a chi-square) is a search miss.
    Where the cold start ends lower, another posture explains the ranges better than the
    one nearest the truth, and no estimator can tell them apart: frames whose estimate lies
    more than ``OTHER_POSTURE`` from that local fit at some joint are counted, and the RMSE
    over the others is reported beside the full one.
    """
    cases = itertools.product(TARGET_LENGTHS, TARGET_ANCHORS, TARGET_MISSING)
    return TargetsReport(sigma, [target_case(sections, anchors, missing, runs, seed, sigma)
                                 for sections, anchors, missing in cases])


# -- the paper ------------------------------------------------------------------------------
def paper_experiments(runs, seed, methods=None, tracking_seconds=60.0, target_runs=None):
    """
    Run every part of the paper's reproduction.

    Parameters
    ----------
    runs : int
        Monte-Carlo runs per point (noise sweeps, NLOS table, xie3dim).
    seed : int
        Seeds every part.
    methods : list of str, optional
        Methods to run where the part has them (default: all).
    tracking_seconds : float
        Length of the tracking part's working cycle.
    target_runs : int, optional
        Postures per target case (default: ``runs``, at most 300).

    Returns
    -------
    PaperReport

    """
    methods = methods or list(METHODS)
    sweep = [m for m in SWEEP_METHODS if m in methods]
    parts = PaperParts(
        sweep_eta=noise_sweep('eta', ETAS, runs, sweep, seed),
        sweep_sigma=noise_sweep('sigma', SIGMAS, runs, sweep, seed),
        nlos=nlos_table(runs, [m for m in NLOS_METHODS if m in methods], seed),
        xie3dim=paper_xie3dim(runs, seed, methods),
        tracking=tracking_suite(methods, tracking_seconds, seed, {}),
        targets=target_cases(target_runs or min(runs, 300), seed))
    return PaperReport(runs, seed, parts)
