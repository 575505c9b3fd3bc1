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
``python3 dev.py bench compare --base REV``: this checkout against another commit, side by side.

Issue #30 asks for speed with the same estimates and the same integrity decisions, and
this machine is shared: a change is measured against its parent in one run, the two trees
in turn. The same frames go through both trees' estimators (the working cycle, three field
cases and uniform garbage, generated here once): per stream and method, the frames whose
status or validity differ, the largest difference of the estimates (metres) and of the
predicted RMSEs (relative), and what each tree's user gets (frames published, their joint
RMSE against the truth, those more than 1 m off and of those the ones whose predicted
RMSE is under a third of the error: confidently wrong); and each tree's CPU per frame on
the working cycle, in alternating rounds of fresh processes: the medians per round, their
ratio, the median ratio.

The other commit is unpacked with ``git archive`` into a folder of the system's temporary
directory named by its hash, and kept (its kernels compile once, about a minute); this
checkout is compared as it is, uncommitted changes to tracked files included (the
heading says "+ changes"; new files not yet added are not counted). Each tree runs this
tree's ``compare_worker.py`` with that tree first on ``sys.path``.
"""
from dataclasses import dataclass
import os
from pathlib import Path
import pickle
import shutil
import subprocess
import sys
import tempfile

from benchmarks import field_bench, speed_bench
from epp_ros.core.simulation import truck_pump
from epp_ros.core.simulation.simulate import truck_outriggers
import numpy as np

__all__ = ['CompareReport', 'run', 'STREAMS']

ROOT = Path(__file__).resolve().parents[1]
WORKER = Path(__file__).resolve().with_name('compare_worker.py')
#: The field cases compared beside the working cycle and the garbage.
FIELD_CASES = ('real_uwb', 'all', 'joystick')
STREAMS = ('working',) + FIELD_CASES + ('garbage',)


@dataclass
class CompareReport:
    """The report of ``python3 dev.py bench compare`` (see :func:`run`)."""

    base: str                   #: the other commit
    head: str                   #: this checkout's commit, "+ changes" when uncommitted
    frames: int                 #: per stream
    rows: list                  #: per stream and method: what differs
    speed: dict                 #: method -> {base, head: CPU ms medians per round}
    repeatable: bool            #: every round of a tree gave the same statuses and estimates
    suite: str = 'compare'


def streams(seconds, seed):
    """
    Return the streams the trees run, and the truth of each.

    Per name: the pump, the estimator's options and the frames (what the workers get);
    and the true joints of each frame (n, p, 3), metres.
    """
    model = truck_pump()
    count = int(round(seconds * speed_bench.RATE))
    working, angles = speed_bench.frames_of(model, count, seed)
    frames = {'working': working, 'garbage': speed_bench.garbage_frames(working, seed)}
    truth = {'working': model.forward_kinematics(angles[:, 0], angles[:, 1:])}
    truth['garbage'] = truth['working']
    for name in FIELD_CASES:
        case = field_bench.case_frames(name, seconds, seed)[0]
        frames[name] = [frame.inputs() for frame in case]
        truth[name] = np.array([frame.joints for frame in case])
    # As the field bench runs them: the outriggers may stand elsewhere than configured.
    options = {'moving_anchors': [int(j) for j in truck_outriggers(model)]}
    geometry = (model.arm_lengths, model.base, model.anchors, model.pivot_offset)
    return ({name: {'model': geometry, 'options': options, 'frames': frames[name]}
             for name in STREAMS}, {name: truth[name] for name in STREAMS})


def unpacked(revision, cache=None):
    """
    Return the commit hash of ``revision`` and a folder holding its tree, kept for reuse.

    In ``cache``, by default ``epp_ros_compare-UID`` in the system's temporary directory
    (the user's own). Unpacked beside it and renamed into place, so that a comparison
    running at the same time never sees a tree half there, nor loses one. ValueError
    where ``revision`` names no commit.
    """
    try:
        sha = _git('rev-parse', '--verify', f'{revision}^{{commit}}').decode().strip()
    except subprocess.CalledProcessError:
        raise ValueError(f'--base {revision!r} names no commit of {ROOT}') from None
    cache = Path(cache or Path(tempfile.gettempdir()) / f'epp_ros_compare-{os.getuid()}')
    folder = cache / sha
    if not folder.is_dir():
        cache.mkdir(mode=0o700, parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=sha + '.', dir=cache))
        subprocess.run(['tar', '-x', '-C', str(partial)], input=_git('archive', sha),
                       check=True)
        try:
            partial.rename(folder)
        except OSError:                     # another comparison put it there first
            shutil.rmtree(partial, ignore_errors=True)
    return sha, folder


def _git(*arguments):
    return subprocess.run(['git', *arguments], cwd=ROOT, capture_output=True,
                          check=True).stdout


def _head():
    """Return this checkout's short hash, and "+ changes" when files differ from it."""
    sha = _git('rev-parse', '--short', 'HEAD').decode().strip()
    changed = _git('status', '--porcelain', '--untracked-files=no').strip()
    return sha + (' + changes' if changed else '')


def _worker(tree, inputs, scratch, label):
    """Run ``compare_worker.py`` on ``tree`` in a fresh process; return its results."""
    outputs = scratch / f'{label}.pickle'
    subprocess.run([sys.executable, str(WORKER), str(tree), str(inputs), str(outputs)],
                   check=True)
    with open(outputs, 'rb') as stream:
        return pickle.load(stream)


def scored(results, truth):
    """
    Return what a user of one tree got on one stream: published, RMSE, > 1 m off, confidently.

    Over the frames published as valid: their joint RMSE against ``truth`` (n, p, 3),
    metres; how many are more than 1 m off (RMS over the joints); of those, how many with
    a predicted RMSE under a third of the error, or none.
    """
    valid = results['valid']
    error = np.sqrt(np.mean(np.sum((results['estimate'] - truth) ** 2, axis=-1), axis=-1))
    wrong = valid & (error > 1.0)
    return {'published': int(valid.sum()),
            'rmse': float(np.sqrt(np.mean(error[valid] ** 2))) if valid.any() else np.nan,
            'wrong': int(wrong.sum()),
            'confidently': int(np.sum(wrong & ~(results['predicted'] >= error / 3.0)))}


def differences(base, head, truth):
    """Return per stream and method what differs between two trees' results, and each's score."""
    rows = []
    for stream, methods in base.items():
        for method, old in methods.items():
            new = head[stream][method]
            moved = np.abs(old['estimate'] - new['estimate'])
            finite = np.isfinite(old['predicted']) & np.isfinite(new['predicted'])
            relative = np.abs(old['predicted'][finite] - new['predicted'][finite]) / np.maximum(
                np.abs(old['predicted'][finite]), np.finfo(float).tiny)
            rows.append({
                'stream': stream, 'method': method, 'frames': len(old['status']),
                'status': int(np.sum(old['status'] != new['status'])),
                'valid': int(np.sum(old['valid'] != new['valid'])),
                'scores': (scored(old, truth[stream]), scored(new, truth[stream])),
                'estimate': float(np.max(moved, initial=0.0, where=np.isfinite(moved))),
                'estimate_nan': int(np.sum(np.any(np.isnan(old['estimate'])
                                                  != np.isnan(new['estimate']), axis=(1, 2)))),
                'predicted': float(np.max(relative, initial=0.0)),
                'predicted_finite': int(np.sum(np.isfinite(old['predicted'])
                                               != np.isfinite(new['predicted'])))})
    return rows


def _same(first, again):
    """Whether two runs of one tree gave the same statuses and estimates."""
    return all(np.array_equal(first[s][m]['status'], again[s][m]['status'])
               and np.array_equal(first[s][m]['estimate'], again[s][m]['estimate'],
                                  equal_nan=True)
               for s in first for m in first[s])


def _medians(results, key):
    """CPU ms per frame on the working cycle after the warm-up, the median, per method."""
    def median(times):
        return float(np.median(times[min(speed_bench.WARM_UP, len(times) // 2):]))
    return {method: median(columns[key]) for method, columns in results['working'].items()}


def run(base='HEAD', methods=speed_bench.METHODS, seconds=30.0, seed=0, rounds=4,
        cache=None):
    """
    Compare this checkout with ``base``: ``rounds`` alternating rounds, ``seconds`` a stream.

    ``cache``: where the other tree is unpacked (:func:`unpacked`).

    Returns
    -------
    CompareReport

    """
    sha, tree = unpacked(base, cache)
    with tempfile.TemporaryDirectory(prefix='epp_ros_compare_') as scratch:
        scratch = Path(scratch)
        inputs = scratch / 'streams.pickle'
        work, truth = streams(seconds, seed)
        with open(inputs, 'wb') as stream:
            pickle.dump({'streams': work, 'methods': list(methods)}, stream)
        runs = {'base': [], 'head': []}
        for index in range(rounds):
            order = ('base', 'head') if index % 2 == 0 else ('head', 'base')
            for label in order:
                runs[label].append(_worker(tree if label == 'base' else ROOT, inputs,
                                           scratch, f'{label}{index}'))
    columns = (('', 'frame_ms'), ('_answer', 'answer_ms'))
    speed = {method: {label + key: [_medians(result, suffix)[method] for result in runs[label]]
                      for label in runs for key, suffix in columns}
             for method in methods}
    repeatable = all(_same(results[0], again) for results in runs.values()
                     for again in results[1:])
    frames = len(runs['base'][0]['working'][methods[0]]['status'])
    rows = differences(runs['base'][0], runs['head'][0], truth)
    return CompareReport(sha[:7], _head(), frames, rows, speed, repeatable)
