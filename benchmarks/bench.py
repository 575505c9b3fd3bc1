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
python3 dev.py bench: speed and accuracy of the estimators, next to the paper's published figures.

Suites:
  xie3dim   The authors' geometry at additive sigma = 1 m, cold start per trial: the mean
            and the RMS of the per-trial RMSE, arm-length error and per-frame time of each
            method (published: the mean over 3,000 trials, and its RMS).
  tracking  The simulated truck pump on a working cycle at 10 Hz, warm-started: RMSE and
            per-frame time, the runtime case.
  latency   A posture_estimator process fed over DDS: latency from a uwb/ranges publish to
            the matching arm_posture receive at 10 and 100 Hz, and the highest frame rate
            sustained with no frame lost and none answered later than 100 ms.
  bags      A synthesised 60 s bag: `epp_bag eval` frames/s, and `epp_bag play --fast`
            through the live estimator node, frames/s and frames lost.
  controller  The node pinned to one core that a busy process shares (a controller's
            budget), the feeder on another, at 10 Hz for --controller-seconds (default
            600) per method (default cepp): latency p50, p90, p99, max, frames
            unanswered. Not default.
  paper     The seed paper's experiments side by side with its figures, every method
            including the baselines (SDP needs cvxpy): RMSE (mean and RMS) vs noise with
            the CRLB, Table 1, Table 3 (NLOS), xie3dim with the authors' variants (EMBED's
            Toh post-processing, CEPP in the true plane), tracking, and the chain's
            targets. Writes paper.md, paper.json and PNG plots into --out. Not part of the
            default run.
  integrity Streams with corrupted frames (all tags, one tag), bursts of garbage, two-anchor
            frames, absurd ranges and degenerate anchor geometries (--seconds each): frames
            reported valid while wrong, time to recover, good frames rejected. Not default.
  driver    The UWB driver's read throughput over TCP and a pty (lines/s, CPU). Not default.
  soak      --frames frames (default 1,000,000) through parser, assembler and estimator
            in-process, --live-frames (100,000) through the live node with epp_bag play
            --fast: frames lost, frames/s, RSS at start, after warm-up and at the end (with
            --json the last line's object has frames, frames_lost, rss_start_mb,
            rss_end_mb). Method: the first of --methods, else chain. Not default.
  fuzz      --inputs generated inputs (default 100,000) per line protocol and per pump
            configuration field; counts every exception that escapes. Not default.
  field     The field effects of core.simulate alone and together (--seeds runs of
            --seconds per case): chain, cepp and track with their defaults, and chain told
            the truth, as RMSE over the clean Cramér–Rao bound; track over the posterior
            bound; the authors' geometry at sigma 1 and 2 m from cold starts (--trials);
            cost of track and chain, and of the chain's fit against scipy. Not default.
  family    The real links' preset (real_uwb) varied as sites and devices vary it: each
            real-link figure doubled, outliers ten times as often and 3 m, device offsets
            0.15 m, and with the other field effects and the joystick (--seeds runs of
            --seconds per case): what each method publishes, its RMSE over the clean bound
            on those frames, frames valid while > 1 m off and confidently so. Not default.
  calibration  Calibration from --seconds of working cycle (--seeds pumps, offsets 0.15 m,
            outriggers 0.3 m off): anchor and link-offset errors, computation time, and chain
            and track over the clean CRLB with the configured and the calibrated model on a
            fresh recording, side by side. Not default.
  speed     CPU time per frame of each method (default chain, cepp, track) over --seconds
            of working cycle at 10 Hz: median, p90, p99, max, against issue #30's targets;
            the chain against scipy's bare fit; refused and garbage frames against good
            ones; the growth with sections and anchors (exponents). Not default.
  compare   This checkout against the commit --base (default HEAD: the uncommitted
            changes): the same frames (working cycle, field cases, garbage; --seconds
            each) through both trees' estimators (--methods, default chain, cepp, track):
            frames whose status or validity differ, the largest estimate and predicted-RMSE
            differences, and CPU per frame in --rounds alternating rounds of fresh
            processes with their ratios. Not default.
Every table ends with the commit it was measured on. ``--option KEY=VALUE`` passes an
option to the estimators (e.g. ``anchor_weight=inf``, ``predict_slew=false``).
"""
import argparse
from pathlib import Path
import sys
from typing import Callable, NamedTuple

from benchmarks import (calibration_bench, compare_bench, driver_bench, experiments,
                        field_bench, fuzz_bench, integrity_bench, soak_bench, speed_bench)
from benchmarks.reports import bench_json, CalibrationReport, commit, markdown
from epp_ros.app.threads import single_blas_thread
from epp_ros.cli.arguments import integer, number, Parser
from epp_ros.core import METHODS
import numpy as np

#: The estimators of the runtime suites by default; the baselines are there on request.
DEFAULT_METHODS = ['epp1', 'epp2', 'cepp', 'chain']


def parse_option(text):
    """``'key=value'`` -> (key, bool, number or string); ``inf`` is a number."""
    key, sep, value = text.partition('=')
    if not sep or not key:
        raise argparse.ArgumentTypeError(f'expected KEY=VALUE, got {text!r}')
    if value.lower() in ('true', 'false'):
        return key, value.lower() == 'true'
    try:
        number = float(value)
        return key, int(number) if number.is_integer() and 'e' not in value.lower() and \
            '.' not in value else number
    except ValueError:
        return key, value


def _methods(args):
    """Return the methods asked for, or the runtime suites' defaults."""
    return args.methods or DEFAULT_METHODS


def _progress(text):
    print(text, flush=True)


def _xie3dim(args):
    return experiments.xie3dim_suite(_methods(args), args.trials, args.seed, args.options)


def _tracking(args):
    return experiments.tracking_suite(_methods(args), args.seconds, args.seed, args.options)


def _latency(args):
    return experiments.latency_suite(_methods(args), args.latency_seconds, args.seed)


def _controller(args):
    return experiments.controller_suite(args.methods or ['cepp'], args.controller_seconds,
                                        args.seed)


def _bags(args):
    return experiments.bags_suite(_methods(args), args.seed)


def _paper(args):
    from benchmarks import paper
    return paper.run(args.out, args.runs, args.seed, args.methods, args.seconds)


def _integrity(args):
    return integrity_bench.run(_methods(args), args.seconds, args.seed, args.options)


def _driver(args):
    return driver_bench.run()


def _soak(args):
    method = (args.methods or ['chain'])[0]
    return soak_bench.run(args.frames, args.live_frames, method, args.seed, _progress,
                          args.lag_seconds)


def _fuzz(args):
    return fuzz_bench.run(args.inputs, args.seed, _progress)


def _field(args):
    return field_bench.run(args.seconds, args.seeds, args.seed, args.trials)


def _family(args):
    return field_bench.run_family(args.seconds, args.seeds)


def _speed(args):
    return speed_bench.run(args.methods or speed_bench.METHODS, int(args.seconds * 10),
                           args.seed)


def _compare(args):
    try:
        return compare_bench.run(args.base, args.methods or speed_bench.METHODS, args.seconds,
                                 args.seed, args.rounds)
    except ValueError as error:
        raise SystemExit(f'python3 dev.py bench compare: {error}') from None


def _calibration(args):
    return CalibrationReport(calibration_bench.run(args.seconds, args.seeds, args.seed))


class Suite(NamedTuple):
    """A suite of ``python3 dev.py bench``: how it runs (arguments -> report), what it takes."""

    run: Callable
    default: bool = False       #: run when no suite is named
    node: bool = False          #: runs posture_estimator processes: no --option
    angles: bool = False        #: simulates angle sensors: tpsm may run


#: The suites, in the order of the help; ``Suite.run`` returns a report for ``reports``.
SUITES = {
    'xie3dim': Suite(_xie3dim, default=True),
    'tracking': Suite(_tracking, default=True, angles=True),
    'latency': Suite(_latency, default=True, node=True),
    'bags': Suite(_bags, default=True, node=True),
    'controller': Suite(_controller, node=True),
    'paper': Suite(_paper, angles=True),
    'integrity': Suite(_integrity),
    'driver': Suite(_driver),
    'soak': Suite(_soak),
    'fuzz': Suite(_fuzz),
    'field': Suite(_field),
    'family': Suite(_family),
    'calibration': Suite(_calibration),
    'speed': Suite(_speed),
    'compare': Suite(_compare),
}


def parser():
    """Return the argument parser of ``python3 dev.py bench``."""
    defaults = [name for name, suite in SUITES.items() if suite.default]
    others = [name for name, suite in SUITES.items() if not suite.default]
    result = Parser(prog='python3 dev.py bench', description=__doc__.lstrip().splitlines()[0],
                    epilog=__doc__.lstrip().split('\n', 1)[1],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    result.add_argument('suites', nargs='*', metavar='suite',
                        help=f'{", ".join(defaults)} (default: these {len(defaults)}), '
                             + ', '.join(others))
    result.add_argument('--methods', nargs='+', choices=list(METHODS),
                        help=f'default: {" ".join(DEFAULT_METHODS)} (paper: all)')
    result.add_argument('--trials', type=int, default=200, help='xie3dim trials')
    result.add_argument('--seconds', type=float, default=60.0,
                        help='tracking duration; integrity: seconds per stream')
    result.add_argument('--latency-seconds', type=float, default=5.0,
                        help='latency: seconds per rate')
    result.add_argument('--controller-seconds', type=float, default=600.0,
                        help='controller: seconds per method (default 600)')
    result.add_argument('--seed', type=int, default=0)
    result.add_argument('--seeds', type=integer(1, 1000), default=2,
                        help='field, family: runs per case; calibration: pumps (default 2)')
    result.add_argument('--option', type=parse_option, action='append', default=[],
                        metavar='KEY=VALUE', help='estimator option, repeatable')
    result.add_argument('--json', action='store_true', help='also print the reports as JSON')
    result.add_argument('--runs', type=int, default=3000,
                        help='paper: Monte-Carlo runs per point (default 3000, as the paper)')
    result.add_argument('--out', type=Path, default=Path('epp_bench_paper'),
                        help='paper: folder for paper.md, paper.json and the plots')
    result.add_argument('--frames', type=integer(2, 10 ** 9), default=1_000_000,
                        help='soak: frames in-process (default 1,000,000)')
    result.add_argument('--live-frames', type=integer(0, 10 ** 7), default=100_000,
                        help='soak: frames through the live node (default 100,000; 0: none)')
    result.add_argument('--lag-seconds', type=number(0, 3600), default=30.0,
                        help='soak: seconds the live estimator is stopped while frames flow '
                             '(default 30; 0: no lag phase)')
    result.add_argument('--base', default='HEAD',
                        help='compare: the commit to compare this checkout with (default HEAD)')
    result.add_argument('--rounds', type=integer(1, 100), default=4,
                        help='compare: alternating rounds of the two trees (default 4)')
    result.add_argument('--inputs', type=integer(1, 10 ** 9), default=100_000,
                        help='fuzz: inputs per protocol and per configuration field')
    return result


def parse_args(argv):
    """Parse and check the arguments; ``suites`` and ``options`` filled in."""
    arguments = parser()
    args = arguments.parse_args(argv)
    args.suites = args.suites or [name for name, suite in SUITES.items() if suite.default]
    unknown = sorted(set(args.suites) - set(SUITES))
    if unknown:
        arguments.error(f'unknown suite(s) {unknown}; choose from {", ".join(SUITES)}')
    args.options = dict(args.option)
    suites = [SUITES[name] for name in args.suites]
    if args.options and any(suite.node for suite in suites):
        arguments.error('--option applies to the in-process suites (xie3dim, tracking); the '
                        'node suites run posture_estimator with its parameters')
    if 'tpsm' in _methods(args) and not all(suite.angles for suite in suites):
        arguments.error('tpsm needs angle sensors, which only the tracking and paper suites '
                        'simulate')
    if args.runs < 1:
        arguments.error('--runs must be >= 1')
    return args


def main(argv=None):
    """Run the suites named on the command line; print their tables (and JSON)."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    single_blas_thread()                # as the nodes and epp_bag run
    reports = []
    for name in args.suites:
        reports.append(SUITES[name].run(args))
        print(markdown(reports[-1]) + '\n', flush=True)
    print(f'commit {commit()}, Python {sys.version.split()[0]}, numpy {np.__version__}'
          + (f', options {args.options}' if args.options else ''))
    if args.json:
        print(bench_json(reports))
    return 0


if __name__ == '__main__':
    sys.exit(main())
