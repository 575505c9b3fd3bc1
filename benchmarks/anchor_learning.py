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
Outriggers that stand elsewhere than configured: counted, learned while running, or not.

``python3 benchmarks/anchor_learning.py [--seconds 60] [--seeds 2]``: the field bench's
cases where the anchors are where configured (``clean``), where the outriggers stand off
(``anchors_moved``: 0.2 m per axis) and real links (``real_uwb``), each method with
``anchor_std`` 0 (every anchor where configured), the default (0.1 m, counted in the
predicted stds, not learned) and 0.1 m learned (``learn_anchors``: the shifts learned with
the common bias), side by side on the same frames: RMSE over the frames published as
valid / clean bound, the fraction published, frames valid while > 1 m off / of those
confidently (a predicted RMSE under a third of the error).
"""
import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmarks import field_bench  # noqa: E402
from epp_ros.core import PostureEstimator  # noqa: E402,I100
from epp_ros.core.estimation import wrong_frames  # noqa: E402
from epp_ros.core.simulation import truck_outriggers  # noqa: E402
import numpy as np  # noqa: E402

CASES = ('clean', 'anchors_moved', 'real_uwb')
METHODS = ('chain', 'track')
#: Column: (anchor_std, learn_anchors).
COLUMNS = {'anchor_std 0': (0.0, False), 'default (0.1 m, counted)': (0.1, False),
           '0.1 m learned': (0.1, True)}


def run(seconds, seeds):
    """Return {(case, method, column): (ratio, published, wrong, confident)}."""
    pooled = {}
    for case in CASES:
        for seed in range(seeds):
            _, bounds, frames, model = field_bench.run_case(case, seconds, seed)
            scored = [frame.stamp >= field_bench.WARM_UP_S for frame in frames]
            for method in METHODS:
                for column, (anchor_std, learn) in COLUMNS.items():
                    estimator = PostureEstimator(model, method, anchor_std=anchor_std,
                                                 learn_anchors=learn,
                                                 moving_anchors=truck_outriggers(model))
                    run = []
                    for frame in frames:
                        estimator.update(**frame.inputs())
                        result = estimator.last_diagnostics
                        run.append((np.mean(np.sum((result['estimate'] - frame.joints) ** 2,
                                                   axis=1)),
                                    result['valid'], result.get('predicted_rmse', np.nan)))
                    # The scored frames (after the warm-up), each beside its clean bound.
                    kept = [row for row, score in zip(run, scored) if score]
                    pooled.setdefault((case, method, column), []).extend(
                        (*row, bound) for row, bound in zip(kept, bounds))
    return {key: _cell(np.array(rows, dtype=float)) for key, rows in pooled.items()}


def _cell(rows):
    squared, published, predicted, bounds = rows.T
    published = published.astype(bool)
    wrong, confident = wrong_frames(squared, published, predicted)
    ratio = np.sqrt(np.mean(squared[published]) / np.mean(bounds[published] ** 2)) \
        if published.any() else float('nan')
    return ratio, float(published.mean()), wrong, confident


def main():
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--seeds', type=int, default=2)
    args = parser.parse_args()
    cells = run(args.seconds, args.seeds)
    print('Each cell: RMSE over the frames published as valid / clean bound (the fraction '
          'published; frames valid while > 1 m off / of those confidently)\n')
    print('| case | method | ' + ' | '.join(COLUMNS) + ' |')
    print('|---|---|' + '---|' * len(COLUMNS))
    for case in CASES:
        for method in METHODS:
            text = ['{:.2f} ({:.0%}; {} / {})'.format(*cells[case, method, column])
                    for column in COLUMNS]
            print(f'| {case} | {method} | ' + ' | '.join(text) + ' |')


if __name__ == '__main__':
    main()
