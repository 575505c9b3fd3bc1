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
One tree's side of ``python3 dev.py bench compare``: ``python compare_worker.py TREE IN OUT``.

Runs in a fresh process with ``TREE`` first on ``sys.path``, so that ``epp_ros`` is that
tree's (another commit's, or this checkout). Reads the streams ``compare_bench`` pickled to
``IN``: per stream, the pump (arm lengths, base, anchors, pivot offset), the estimator's
options and the frames (``PostureEstimator.update``'s keywords); runs each method on each
stream; pickles to ``OUT``, per stream and method, each frame's status, validity, estimate
(p, 3), predicted RMSE and CPU milliseconds (the ``update``, and the ``update`` with the
``settle`` after it where the tree has one). Uses only what every tree since the
compiled kernels (``methods/kernels.py``) offers: plain types in, plain types out.
"""
import pickle
import sys
import time


def _run(estimator, frames):
    """Return one stream's per-frame results from ``estimator``."""
    import numpy as np
    settle = getattr(estimator, 'settle', lambda: None)
    columns = {'status': [], 'valid': [], 'estimate': [], 'predicted': [], 'answer_ms': [],
               'frame_ms': []}
    for frame in frames:
        began = time.process_time()
        returned = estimator.update(**frame)
        answered = time.process_time()
        settle()
        ended = time.process_time()
        diagnostics = estimator.last_diagnostics
        columns['status'].append(str(diagnostics['status']))
        columns['valid'].append(bool(diagnostics['valid']))
        columns['estimate'].append(np.array(diagnostics.get('estimate', returned), dtype=float))
        predicted = diagnostics.get('predicted_rmse')
        columns['predicted'].append(np.nan if predicted is None else float(predicted))
        columns['answer_ms'].append(1e3 * (answered - began))
        columns['frame_ms'].append(1e3 * (ended - began))
    return {key: np.array(value) for key, value in columns.items()}


def main(tree, inputs, outputs):
    """Run every method on every stream of ``inputs`` with ``tree``'s estimators."""
    sys.path.insert(0, tree)
    import epp_ros
    from epp_ros.app.threads import single_blas_thread
    from epp_ros.core import BoomModel, PostureEstimator
    from epp_ros.core.estimation.methods.kernels import compile_fit
    if not epp_ros.__file__.startswith(tree):
        raise SystemExit(f'compare_worker: epp_ros came from {epp_ros.__file__}, not {tree}')
    single_blas_thread()
    compile_fit()
    with open(inputs, 'rb') as stream:
        work = pickle.load(stream)
    results = {}
    for name, stream in work['streams'].items():
        model = BoomModel(*stream['model'])
        results[name] = {method: _run(PostureEstimator(model, method, **stream['options']),
                                      stream['frames'])
                         for method in work['methods']}
    with open(outputs, 'wb') as stream:
        pickle.dump(results, stream)


if __name__ == '__main__':
    main(*sys.argv[1:4])
