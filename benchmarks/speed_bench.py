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
``python3 dev.py bench speed``: CPU time per frame of the estimators, as issue #30 states it.

CPU time (``time.process_time``) around ``PostureEstimator.update`` and the ``settle`` after
it (what the frame teaches the learners), one BLAS thread as the nodes run, on the
simulated truck pump's working cycle at sigma 0.1 m after 30 warm-up frames. Rows: each
method's median, p90, p99 and max per frame, and of the ``update`` alone (the frame's
answer, what a node publishes after); frames published; the
chain's update against scipy's bare ``least_squares`` fit of the same frames; refused frames
(``lowest_joint`` 10 m: every frame refused; uniform garbage 0-80 m) against good ones; and
the growth with anchors and sections, with the exponent of a log-log fit.
"""
from dataclasses import dataclass, field
import time

from benchmarks.field_bench import scipy_chain_fit
from epp_ros.core import PostureEstimator
from epp_ros.core.model.boom import BoomModel
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation import observe, RangeNoise, truck_pump, working_cycle
import numpy as np

__all__ = ['frames_of', 'garbage_frames', 'METHODS', 'SpeedReport', 'run', 'TARGETS']

WARM_UP = 30
RATE = 10.0
SIGMA = 0.1
#: The issue's targets, milliseconds of CPU per frame: (median, p99).
TARGETS = {'chain': (1.0, 3.0), 'cepp': (2.0, 5.0), 'track': (1.5, 4.0)}
#: The methods timed by default (``speed``, ``compare``): those with targets.
METHODS = tuple(TARGETS)
#: The pumps of the growth rows: (sections, anchors).
SECTIONS = (3, 5, 8, 12)
ANCHORS = (4, 6, 9, 12, 16)


def frames_of(model, count, seed):
    """Return ``count`` frames of the working cycle (``update``'s keywords) and the angles."""
    motion = working_cycle(model, duration=count / RATE, rate=RATE,
                           rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    noise = RangeNoise(sigma=SIGMA)
    frames = []
    for k in range(count):
        frame, _ = observe(model, motion.slew[k], motion.pitches[k], rng, noise)
        frame['stamp'] = k / RATE
        frames.append(frame)
    return frames, np.c_[motion.slew[:count], motion.pitches[:count]]


def garbage_frames(frames, seed):
    """Return ``frames`` with every range drawn uniformly from 0-80 m (the hostile case)."""
    rng = np.random.default_rng(seed + 2)
    return [{'ranges': rng.uniform(0.0, 80.0, frame['ranges'].shape), 'stamp': frame['stamp']}
            for frame in frames]


def frame_times(model, method, frames, **options):
    """
    Return CPU milliseconds per frame after the warm-up, how many were published, and the answers.

    A frame's time is its ``update`` and what it teaches (``settle``); its answer's, the
    ``update``'s alone: what stands between the ranges and the posture.
    """
    estimator = PostureEstimator(model, method, **options)
    times, published, answers = [], 0, []
    for k, frame in enumerate(frames):
        began = time.process_time()
        estimator.update(**frame)
        answered = time.process_time()
        estimator.settle()
        spent = time.process_time() - began
        if k >= WARM_UP:
            times.append(1e3 * spent)
            published += bool(estimator.last_diagnostics.valid)
            answers.append(1e3 * (answered - began))
    return np.array(times), published, np.array(answers)


def percentiles(times):
    """Median, p90, p99 and max of ``times``."""
    return {'median': float(np.median(times)), 'p90': float(np.percentile(times, 90)),
            'p99': float(np.percentile(times, 99)), 'max': float(np.max(times))}


def scipy_fit_ms(model, frames, angles):
    """Median CPU milliseconds of scipy's LM fit of the chain from a warm start, per frame."""
    times = []
    rng = np.random.default_rng(0)
    for frame, truth in zip(frames[WARM_UP:], angles[WARM_UP:]):
        residuals = Residuals(model, Measurements.ranges_only(frame['ranges']),
                              SensorNoise(SIGMA))
        start = truth + rng.normal(0.0, 0.02, truth.size)     # a frame away
        began = time.process_time()
        scipy_chain_fit(residuals, start)
        times.append(1e3 * (time.process_time() - began))
    return float(np.median(times))


def growth_pump(sections, anchors, seed=0):
    """Return a 40 m boom of ``sections`` equal sections: the truck's anchors, then others."""
    truck = truck_pump()
    rng = np.random.default_rng(seed)
    extra = [rng.uniform([-7.0, -4.0, 0.2], [7.0, 4.0, 3.5]) for _ in range(anchors)]
    return BoomModel(np.full(sections, 40.0 / sections), truck.base,
                     np.vstack([truck.anchors] + extra)[:anchors])


def growth_rows(methods, frames_per_pump, seed):
    """Median ms per frame on pumps of more sections and anchors; the log-log exponents."""
    axes = (('sections', SECTIONS, 'anchors', 6), ('anchors', ANCHORS, 'sections', 5))
    rows, exponents = [], {}
    for axis, values, other, held in axes:
        picked = []
        for value in values:
            shape = {axis: value, other: held}
            model = growth_pump(shape['sections'], shape['anchors'], seed)
            frames, _ = frames_of(model, WARM_UP + frames_per_pump, seed)
            medians = {method: float(np.median(frame_times(model, method, frames)[0]))
                       for method in methods}
            picked.append({**shape, **medians})
        exponents[axis] = {}
        for method in methods:
            times = [row[method] for row in picked]
            exponents[axis][method] = float(np.polyfit(np.log(values), np.log(times), 1)[0])
        rows += picked
    return rows, exponents


@dataclass
class SpeedReport:
    """The report of ``python3 dev.py bench speed`` (see :func:`run`)."""

    frames: int
    rows: dict                  #: method -> percentiles, published, refused ratios
    scipy_fit_ms: float
    growth: list = field(default_factory=list)
    exponents: dict = field(default_factory=dict)
    suite: str = 'speed'


def run(methods, frames, seed, growth_frames=20):
    """Run the speed suite: ``frames`` measured frames per method and case."""
    model = truck_pump()
    good, angles = frames_of(model, WARM_UP + frames, seed)
    garbage = garbage_frames(good, seed)
    rows = {}
    for method in methods:
        times, published, answers = frame_times(model, method, good)
        low = frame_times(model, method, good, lowest_joint=10.0)[0]
        junk = frame_times(model, method, garbage)[0]
        rows[method] = {**percentiles(times), 'published': published,
                        'refused_median': float(np.median(low)),
                        'garbage_median': float(np.median(junk)),
                        'garbage_p99': float(np.percentile(junk, 99)),
                        'answer_median': float(np.median(answers)),
                        'answer_p99': float(np.percentile(answers, 99))}
    growth, exponents = growth_rows([m for m in ('chain', 'cepp') if m in methods],
                                    growth_frames, seed) if growth_frames else ([], {})
    return SpeedReport(frames, rows, scipy_fit_ms(model, good, angles), growth, exponents)
