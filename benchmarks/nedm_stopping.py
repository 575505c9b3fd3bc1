#!/usr/bin/env python3
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
This checkout's ``nearest_edm`` against another revision's, in the EDM estimators, side by side.

    python3 benchmarks/nedm_stopping.py [--reference REV] [--seconds S] [--cases a,b]

Runs epp1, epp2 and cepp on frames of ``python3 dev.py bench field`` cases twice, frame by frame in
turn: with this checkout's ``nearest_edm`` and with the one at git revision ``REV``
(default cb73d97, the last with the old rule: relative change of sqrt(f + c p) <= tol).
Prints per method and case the median and p99 CPU time per frame, the ratio of the two,
the joint RMSE of the frames published as valid, the frames published, those published
while more than 1 m off (and of them, those whose predicted RMSE said too little), how many of
the solver's calls ended converged, and against this checkout's run the frames whose
validity differs and the largest joint difference (m) where both are valid; all after the
field suite's warm-up.
"""
import argparse
from pathlib import Path
import subprocess
import sys
import time
import types

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import field_bench  # noqa: E402
from epp_ros.core import PostureEstimator  # noqa: E402,I100
from epp_ros.core.estimation import wrong_frames  # noqa: E402
from epp_ros.core.estimation.methods import epp  # noqa: E402
from epp_ros.core.simulation import field_effects, simulate_field, truck_pump  # noqa: E402
from epp_ros.core.solvers import nedm  # noqa: E402
import numpy as np  # noqa: E402


def _reference_solver(revision):
    """Return ``nearest_edm`` of the solver module at ``revision`` (either layout)."""
    for path, package in (('epp_ros/core/solvers/nedm.py', 'epp_ros.core.solvers'),
                          ('epp_ros/core/nedm.py', 'epp_ros.core')):
        shown = subprocess.run(['git', 'show', f'{revision}:{path}'], cwd=ROOT,
                               capture_output=True, text=True)
        if shown.returncode == 0:
            break
    else:
        raise SystemExit(f'nedm_stopping: no nedm.py at {revision}')
    source = shown.stdout
    module = types.ModuleType(f'{package}.nedm_reference')
    module.__package__ = package
    exec(compile(source, f'nedm.py@{revision}', 'exec'), module.__dict__)
    return module.nearest_edm


def _counting(solver, counts):
    def call(*args, **kwargs):
        result = solver(*args, **kwargs)
        counts['calls'] += 1
        counts['converged'] += bool(result.converged)
        counts['iterations'] += result.iterations
        return result
    return call


def _frames(case, seconds, seed):
    names, motion_name = field_bench.CASES[case]
    model = truck_pump()
    rng = np.random.default_rng([seed, sum(map(ord, case))])
    effects = field_effects(names) if names else field_bench.FieldEffects()
    motion = field_bench._motion(motion_name, model, seconds, rng)
    return model, simulate_field(model, motion, seconds, effects, rng, 0.1)


def _agreement(first, other):
    """Frames whose validity differs, and the largest joint difference where both are valid."""
    differ, largest = 0, 0.0
    for valid, estimate, other_valid, other_estimate in zip(
            first['decisions'], first['estimates'], other['decisions'], other['estimates']):
        differ += valid != other_valid
        if valid and other_valid:
            largest = max(largest, float(np.max(np.abs(estimate - other_estimate))))
    return differ, largest


def _entry(model, method):
    """Return what one solver's run records, empty."""
    return {'estimator': PostureEstimator(model, method), 'times': [], 'errors': [],
            'valid': 0, 'decisions': [], 'estimates': [], 'predicted': [],
            'counts': {'calls': 0, 'converged': 0, 'iterations': 0}}


def _record(entry, frame, result):
    """Add a scored frame's decision, estimate and error to ``entry``."""
    entry['decisions'].append(bool(result['valid']))
    entry['estimates'].append(result.get('estimate'))
    if result['valid']:
        entry['valid'] += 1
        estimate = result.get('estimate')
        entry['errors'].append(np.mean(np.sum((estimate - frame.joints) ** 2, axis=1)))
        entry['predicted'].append(result.get('predicted_rmse', np.nan))


def _row(case, method, name, entry, first, scored):
    """Return one printed row: ``entry``'s figures, agreement with ``first``'s."""
    times = 1e3 * np.array(entry['times'])
    counts = entry['counts']
    rmse = f'{np.sqrt(np.mean(entry["errors"])):.3f}' if entry['errors'] else '–'
    differ, largest = _agreement(first, entry)
    wrong, confident = wrong_frames(entry['errors'], np.ones(len(entry['errors'])),
                                    entry['predicted'])
    ratio = np.median(entry['times']) / np.median(first['times'])
    return (f'| {case} | {method} | {name} | {np.median(times):.2f} | '
            f'{np.percentile(times, 99):.2f} | {ratio:.2f} | {rmse} | '
            f'{entry["valid"]}/{scored} | {wrong}, {confident} | '
            f'{counts["converged"]}/{counts["calls"]} | '
            f'{counts["iterations"] / max(counts["calls"], 1):.1f} | {differ} | '
            f'{largest:.2g} |')


def run(solvers, methods, cases, seconds, seed):
    """Print one row per (case, method, solver)."""
    print('| case | method | solver | median ms | p99 ms | time ratio | RMSE valid m '
          '| published | wrong, confidently | converged calls | iterations/call '
          '| decisions differ | max difference m |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    for case in cases:
        model, frames = _frames(case, seconds, seed)
        scored = sum(frame.stamp >= field_bench.WARM_UP_S for frame in frames)
        for method in methods:
            runs = {name: _entry(model, method) for name in solvers}
            for frame in frames:
                for name, solver in solvers.items():
                    entry = runs[name]
                    epp.nearest_edm = _counting(solver, entry['counts'])
                    began = time.process_time()
                    entry['estimator'].update(**frame.inputs())
                    entry['times'].append(time.process_time() - began)
                    if frame.stamp >= field_bench.WARM_UP_S:
                        _record(entry, frame, entry['estimator'].last_diagnostics)
            first = runs[next(iter(solvers))]
            for name, entry in runs.items():
                print(_row(case, method, name, entry, first, scored), flush=True)
    epp.nearest_edm = nedm.nearest_edm


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--reference', default='cb73d97')
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--methods', default='epp1,epp2,cepp')
    parser.add_argument('--cases', default='clean,nlos_persistent')
    args = parser.parse_args(argv)
    solvers = {'this': nedm.nearest_edm, args.reference: _reference_solver(args.reference)}
    run(solvers, args.methods.split(','), args.cases.split(','), args.seconds, args.seed)


if __name__ == '__main__':
    main()
