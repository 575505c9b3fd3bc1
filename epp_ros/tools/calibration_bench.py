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
``epp_bench calibration``: calibrate from a recording, then track with the calibration.

Each seed simulates the truck pump (``core.simulate.truck_pump``) with tag and anchor
range offsets of 0.15 m (standard deviation, per device), the four outrigger anchors 0.3 m
(per axis) from their configured places and range noise sigma 0.1 m, and records
``seconds`` of a working cycle at 10 Hz. ``core.calibrate`` fits it with the turret and the
cab fixed (they define the truck frame): the anchor error (largest over the free anchors),
the link offsets' error (tag + anchor, RMS) and the computation time. Then, on a fresh
recording of the same pump (another seed: motion and noise), chain and track with the
configured model and with the calibrated one, side by side, as RMSE over the clean
line-of-sight Cramér–Rao bound (first ``WARM_UP_S`` not scored).
"""
import time

from epp_ros.core import calibrate, PostureEstimator
from epp_ros.core.bounds import crlb
from epp_ros.core.simulate import FieldEffects, FieldSimulator, truck_pump, WorkingMotion
import numpy as np

__all__ = ['run', 'markdown', 'TARGETS']

RATE = 10.0             #: frames per second
WARM_UP_S = 5.0         #: seconds of the fresh recording not scored
OFFSET = 0.15           #: m, std of each tag's and anchor's range offset
SHIFT = 0.3             #: m per axis, std of how far each outrigger anchor is off
SIGMA = 0.1             #: m, range noise
FIXED = (0, 5)          #: the turret and the cab (truck_pump's anchor order)
OUTRIGGERS = (1, 2, 3, 4)
METHODS = ('chain', 'track')
#: The issue's targets: metres, metres, seconds, and ratios to the clean bound.
TARGETS = {'anchor_m': 0.05, 'link_offset_m': 0.03, 'seconds': 30.0, 'chain': 1.2,
           'track': 0.8}


def _simulator(model, seed, truth=None):
    """Return a field simulator of the pump; with ``truth``, the same pump as it."""
    effects = FieldEffects(sigma=SIGMA, tag_offset=OFFSET, anchor_offset=OFFSET,
                           anchor_shift=SHIFT, moving_anchors=OUTRIGGERS)
    simulator = FieldSimulator(model, effects, np.random.default_rng(seed), 1.0 / RATE)
    if truth is not None:
        simulator.true_anchors = truth.true_anchors.copy()
        simulator.tag_offsets = truth.tag_offsets.copy()
        simulator.anchor_offsets = truth.anchor_offsets.copy()
    return simulator


def _record(model, simulator, seconds, seed):
    """Return the frames of ``seconds`` of a working cycle."""
    motion = WorkingMotion(model, np.random.default_rng([seed, 1]))
    return [simulator.frame(motion, index / RATE) for index in range(int(seconds * RATE))]


def _ratios(models, frames, true_model):
    """Return each (name, method)'s RMSE over the clean bound on ``frames``."""
    scored = [frame for frame in frames if frame.stamp >= WARM_UP_S]
    bounds = np.array([crlb(true_model, f.slew_true, f.pitches_true, SIGMA).rmse
                       for f in scored])
    ratios = {}
    for name, model in models.items():
        for method in METHODS:
            estimator = PostureEstimator(model, method)
            squared = []
            for frame in frames:
                returned = estimator.update(**frame.inputs())
                if frame.stamp >= WARM_UP_S:
                    estimate = estimator.last_diagnostics.get('estimate', returned)
                    squared.append(np.mean(np.sum((estimate - frame.joints) ** 2, axis=1)))
            ratios[f'{method} {name}'] = float(np.sqrt(np.mean(squared)
                                                       / np.mean(bounds ** 2)))
    return ratios


def run_seed(seconds, seed):
    """Return one seed's calibration errors, time, verdict and ratios."""
    model = truck_pump()
    truth = _simulator(model, [seed, 0])
    frames = _record(model, truth, seconds, seed)
    ranges = np.array([frame.ranges for frame in frames])
    result = calibrate(model, ranges, fixed_anchors=FIXED, sigma=SIGMA)
    true_links = truth.tag_offsets[:, None] + truth.anchor_offsets[None, :]
    free = list(OUTRIGGERS)
    true_model = model.with_calibration(truth.true_anchors, truth.anchor_offsets,
                                        truth.tag_offsets)
    fresh = _record(model, _simulator(model, [seed, 2], truth), seconds, seed + 10 ** 6)
    return {'seed': seed, 'status': result.status, 'seconds': result.seconds,
            'anchor_m': float(np.max(np.linalg.norm(result.anchors[free]
                                                    - truth.true_anchors[free], axis=1))),
            'anchor_std_m': float(np.max(np.linalg.norm(result.anchor_std[free], axis=1))),
            'link_offset_m': float(np.sqrt(np.mean((result.link_offsets - true_links) ** 2))),
            'rms_before_m': result.rms_before, 'rms_after_m': result.rms_after,
            **_ratios({'configured': model, 'calibrated': result.model}, fresh,
                      true_model)}


def run(seconds=60.0, seeds=2, seed=0):
    """Run ``seeds`` pumps (seeds ``seed``, ``seed + 1``, ...); the report of the suite."""
    began = time.perf_counter()
    rows = [run_seed(seconds, seed + index) for index in range(seeds)]
    return {'suite': 'calibration', 'seconds': seconds, 'seeds': seeds, 'rows': rows,
            'wall_s': time.perf_counter() - began}


def _cell(value, target, digits=3):
    return f'{value:.{digits}f}' + (' (!)' if value > target else '')


def markdown(report):
    """Return the report as the README's table."""
    columns = [f'{method} {name}' for name in ('configured', 'calibrated')
               for method in METHODS]
    lines = [f'### Calibration: {report["seconds"]:g} s of working cycle at {RATE:g} Hz, '
             f'offsets {OFFSET:g} m, outriggers {SHIFT:g} m off, sigma {SIGMA:g} m, turret '
             'and cab fixed; then RMSE / clean CRLB on a fresh recording', '',
             '| seed | verdict | anchors, max [m] | link offsets, RMS [m] | time [s] | '
             'range RMS before -> after [m] | ' + ' | '.join(columns) + ' |',
             '|---|---|---|---|---|---|' + '---|' * len(columns)]
    for row in report['rows']:
        ratios = [_cell(row[c], TARGETS[c.split()[0]], 2) if c.endswith('calibrated')
                  else f'{row[c]:.2f}' for c in columns]
        lines.append(f'| {row["seed"]} | {row["status"]} | '
                     f'{_cell(row["anchor_m"], TARGETS["anchor_m"])} | '
                     f'{_cell(row["link_offset_m"], TARGETS["link_offset_m"])} | '
                     f'{_cell(row["seconds"], TARGETS["seconds"], 1)} | '
                     f'{row["rms_before_m"]:.3f} -> {row["rms_after_m"]:.3f} | '
                     + ' | '.join(ratios) + ' |')
    lines += ['', f'Targets: anchors <= {TARGETS["anchor_m"] * 100:g} cm, link offsets <= '
              f'{TARGETS["link_offset_m"] * 100:g} cm, <= {TARGETS["seconds"]:g} s of '
              f'computation; with the calibrated model chain <= {TARGETS["chain"]} and track '
              f'<= {TARGETS["track"]} x the clean bound; (!) misses one.']
    return '\n'.join(lines)
