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
epp_bench: speed and accuracy of the estimators, next to the paper's published figures.

Suites:
  xie3dim   The authors' geometry at additive sigma = 1 m, cold start per trial: RMSE,
            arm-length error and per-frame time of each method (published: one trial).
  tracking  The simulated truck pump on a working cycle at 10 Hz, warm-started: RMSE and
            per-frame time, the runtime case.
  latency   A posture_estimator process fed over DDS: latency from a uwb/ranges publish to
            the matching arm_posture receive at 10 and 100 Hz, and the highest frame rate
            sustained with no frame lost and none answered later than 100 ms.
  bags      A synthesised 60 s bag: `epp_bag eval` frames/s, and `epp_bag play --fast`
            through the live estimator node, frames/s and frames lost.
  paper     The seed paper's experiments side by side with its figures, every method
            including the baselines (SDP needs cvxpy): RMSE vs noise with the CRLB,
            Table 1, Table 3 (NLOS), xie3dim, tracking, and the chain's targets. Writes
            paper.md, paper.json and PNG plots into --out. Not part of the default run.
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
  calibration  Calibration from --seconds of working cycle (--seeds pumps, offsets 0.15 m,
            outriggers 0.3 m off): anchor and link-offset errors, computation time, and chain
            and track over the clean CRLB with the configured and the calibrated model on a
            fresh recording, side by side. Not default.
Every table ends with the commit it was measured on. ``--option KEY=VALUE`` passes an
option to the estimators (e.g. ``anchor_weight=inf``, ``predict_slew=false``).
"""
import argparse
import json
from pathlib import Path
import subprocess
import sys
import time

from epp_ros.arguments import integer, Parser
from epp_ros.core import METHODS, PostureEstimator
from epp_ros.core.bounds import crlb
from epp_ros.core.chain import angles_from_joints
from epp_ros.core.measurements import Measurements, SensorNoise
from epp_ros.core.metrics import frame_rmse, pooled_rmse
from epp_ros.core.simulate import (AngleNoise, observe, RangeNoise, truck_pump, working_cycle,
                                   XIE3DIM, xie3dim)
import numpy as np

PUBLISHED_XIE3DIM = {'cepp': ('EMBED/CEPP', XIE3DIM['published_mean_rmse_m']['EMBED_CEPP']),
                     'srls': ('SR-LS 3-D', XIE3DIM['published_mean_rmse_m']['SR-LS_3D']),
                     'sdp': ('SDP 3-D', XIE3DIM['published_mean_rmse_m']['SDP_3D'])}
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


def commit():
    try:
        return subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                              text=True, cwd=Path(__file__).resolve().parent,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


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
    that may be published (``epp_bench integrity`` scores that).
    """
    held = estimator.update(**frame)
    return estimator.last_diagnostics.get('estimate', held)


def run_frames(estimator, frames, truths, cold=False, fused=False):
    """
    Feed frames to an estimator; per-frame RMSE, arm-length error and wall time.

    ``frames`` are range arrays (p, m) or dicts of ``update`` keywords, passed through
    :func:`method_inputs`. ``cold``: forget the warm start before each frame.
    """
    rmses, length_errors, times = [], [], []
    for frame, truth in zip(frames, truths):
        frame = method_inputs(estimator.method, frame, fused)
        if cold:
            estimator.reset()
        start = time.perf_counter()
        estimate = method_estimate(estimator, frame)
        times.append(time.perf_counter() - start)
        rmses.append(float(frame_rmse(estimate, truth)))
        length_errors.append(estimator.last_diagnostics['arm_length_error'])
    return np.array(rmses), np.array(length_errors), np.array(times)


def summarize(rmses, lengths, times):
    """Pooled RMSE, mean arm-length error per section and per-frame milliseconds."""
    return {'rmse_m': pooled_rmse(rmses), 'arm_length_error_m': lengths.mean(axis=0).tolist(),
            'ms_median': 1e3 * float(np.median(times)),
            'ms_p99': 1e3 * float(np.percentile(times, 99))}


#: Options that make a method the one the paper published, where ours differ by default:
#: CEPP's NLOS reweighting (H = 1 in the paper).
AS_PUBLISHED = {'cepp': {'irls_iterations': 0}}


def method_options(method, options, sigma):
    """Return the user's options, plus the suite's range noise (every method is told it)."""
    return options if 'sigma' in options else dict(options, sigma=sigma)


def published_options(method, options):
    """
    Return the options of a paper reproduction: the method as published, told the truth.

    The noise is what the suite simulates, so nothing is learned.
    """
    return {**AS_PUBLISHED.get(method, {}), 'learn_noise': False, **options}


def xie3dim_suite(methods, trials, seed, options):
    model, truth = xie3dim()
    rng = np.random.default_rng(seed)
    frames = [RangeNoise(sigma=1.0).apply(model.ranges(truth), rng)[0] for _ in range(trials)]
    rows = []
    for method in methods:
        rmses, lengths, times = run_frames(
            PostureEstimator(model, method, **published_options(
                method, method_options(method, options, 1.0))), frames,
            [truth] * len(frames), cold=True)
        label, published = PUBLISHED_XIE3DIM.get(method, ('', None))
        rows.append({'method': method, **summarize(rmses, lengths, times),
                     'published': None if published is None else f'{published} ({label})'})
    slew, pitches = angles_from_joints(model, truth)
    bound = crlb(model, slew, pitches, 1.0).rmse
    for row in rows:
        row['crlb_m'] = bound
    return {'suite': 'xie3dim', 'trials': trials, 'sigma_m': 1.0, 'rows': rows}


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
    variants = [(method, method, False, {}) for method in methods]
    if 'chain' in methods and 'tpsm' in methods:
        variants.append(('chain+angles', 'chain', True, angles))
    fused_noise = SensorNoise(0.1, 0.1, **angles)
    bounds = {False: [], True: []}
    for slew, pitches, frame in zip(trajectory.slew, trajectory.pitches, frames):
        bounds[False].append(crlb(model, slew, pitches, 0.1, np.isfinite(frame['ranges'])).rmse)
        bounds[True].append(crlb(model, slew, pitches, fused_noise,
                                 Measurements.clean(model, **frame)[0]).rmse)
    rows = []
    for label, method, fused, extra in variants:
        estimator = PostureEstimator(model, method,
                                     **method_options(method, dict(options, **extra), 0.1))
        rmses, lengths, times = run_frames(estimator, frames, trajectory.joints, fused=fused)
        rows.append({'method': label, **summarize(rmses, lengths, times), 'published': None,
                     'crlb_m': pooled_rmse(bounds[fused])})
    return {'suite': 'tracking', 'frames': len(frames), 'sigma_m': 0.1, 'dropout': 0.05,
            'rows': rows}


def latency_suite(methods, seconds, seed):
    """Latency and throughput of the estimator node, measured from another process."""
    from epp_ros.tools.node_bench import measure_latency, sustained_rate
    model = truck_pump()
    trajectory = working_cycle(model, 600.0, 10.0, rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    frames = [RangeNoise(sigma=0.1).apply(model.ranges(j), rng)[0]
              for j in trajectory.joints[:2000]]
    rows = []
    for method in methods:
        row = {'method': method}
        for rate in (10.0, 100.0):
            latencies, lost = measure_latency(method, frames, rate, seconds)
            row[f'p50_ms_{rate:g}hz'] = 1e3 * float(np.median(latencies))
            row[f'p99_ms_{rate:g}hz'] = 1e3 * float(np.percentile(latencies, 99))
            row[f'lost_{rate:g}hz'] = lost
        row['sustained_hz'] = sustained_rate(method, frames)
        rows.append(row)
    return {'suite': 'latency', 'seconds': seconds, 'rows': rows}


def bags_suite(methods, seed):
    """Offline evaluation and fast replay through the node, frames per second."""
    import tempfile
    from epp_ros import bags
    from epp_ros.config import load_pump_config
    from epp_ros.tools.node_bench import replay_rate
    config = load_pump_config()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / 'cycle'
        frames = bags.synthesize(bag, config, duration=60.0, sigma=0.1, seed=seed)[bags.RANGES]
        for method in methods:
            start = time.perf_counter()
            bags.evaluate(bag, config, method)
            eval_rate = frames / (time.perf_counter() - start)
            play_rate, lost = replay_rate(method, bag, frames)
            rows.append({'method': method, 'eval_fps': eval_rate, 'play_fps': play_rate,
                         'lost': lost})
    return {'suite': 'bags', 'frames': frames, 'rows': rows}


def markdown(report):
    if report['suite'] == 'integrity':
        from epp_ros.tools import integrity_bench
        return integrity_bench.markdown(report)
    if report['suite'] == 'field':
        from epp_ros.tools import field_bench
        return field_bench.markdown(report)
    if report['suite'] == 'calibration':
        from epp_ros.tools import calibration_bench
        return calibration_bench.markdown(report)
    if report['suite'] in ('soak', 'fuzz'):
        from epp_ros.tools import fuzz_bench, soak_bench
        return (soak_bench if report['suite'] == 'soak' else fuzz_bench).markdown(report)
    if report['suite'] == 'driver':
        from epp_ros.tools.driver_bench import format_rows
        return '\n'.join(['### UWB driver: lines read per second over TCP and a pty', '',
                          '```', format_rows(report['rows']), '```'])
    if report['suite'] == 'bags':
        lines = [f'### A {report["frames"]}-frame bag: offline eval, and play --fast through '
                 'the estimator node', '',
                 '| method | eval [frames/s] | play --fast [frames/s] | frames lost |',
                 '|---|---|---|---|']
        lines += [f'| {r["method"]} | {r["eval_fps"]:.0f} | {r["play_fps"]:.0f} | '
                  f'{r["lost"]} |' for r in report['rows']]
        return '\n'.join(lines)
    if report['suite'] == 'latency':
        lines = [f'### posture_estimator over DDS, uwb/ranges publish -> arm_posture receive '
                 f'({report["seconds"]:g} s per rate)', '',
                 '| method | 10 Hz p50 [ms] | p99 | lost | 100 Hz p50 [ms] | p99 | lost | '
                 'sustained: none lost, all < 100 ms [frames/s] |',
                 '|---|---|---|---|---|---|---|---|']
        for row in report['rows']:
            lines.append(f'| {row["method"]} | {row["p50_ms_10hz"]:.1f} | '
                         f'{row["p99_ms_10hz"]:.1f} | {row["lost_10hz"]} | '
                         f'{row["p50_ms_100hz"]:.1f} | {row["p99_ms_100hz"]:.1f} | '
                         f'{row["lost_100hz"]} | {row["sustained_hz"]:g} |')
        return '\n'.join(lines)
    if report['suite'] == 'xie3dim':
        title = (f'xie3dim (authors\' geometry), additive sigma = 1 m, {report["trials"]} '
                 'trials, cold start')
    else:
        title = (f'truck pump, working cycle at 10 Hz, {report["frames"]} frames, sigma = '
                 f'{report["sigma_m"]} m, {report["dropout"]:.0%} dropouts, warm start')
    lines = [f'### {title}', '',
             '| method | RMSE [m] | RMSE / CRLB | mean arm-length error [m] | ms/frame p50 | '
             'p99 | published RMSE [m] |', '|---|---|---|---|---|---|---|']
    for row in report['rows']:
        lines.append(f'| {row["method"]} | {row["rmse_m"]:.3f} | '
                     f'{row["rmse_m"] / row["crlb_m"]:.2f} | '
                     f'{max(row["arm_length_error_m"]):.1e} | {row["ms_median"]:.2f} | '
                     f'{row["ms_p99"]:.2f} | {row["published"] or "-"} |')
    lines += ['', 'Cramér–Rao bound of the chain model from the ranges (RMSE): '
              f'{report["rows"][0]["crlb_m"]:.3f} m.']
    fused = [row for row in report['rows'] if row['method'] == 'chain+angles']
    if fused:
        lines += [f'chain+angles also fuses the inclinometers and slew encoder that tpsm uses '
                  f'alone; its bound: {fused[0]["crlb_m"]:.3f} m.']
    if report['suite'] == 'xie3dim':
        published = ', '.join(f'{name} {value}' for name, value
                              in XIE3DIM['published_mean_rmse_m'].items())
        lines += ['', f'Published by the authors (one trial, MATLAB): {published}.']
    return '\n'.join(lines)


def main(argv=None):
    parser = Parser(prog='epp_bench',
                    description=__doc__.lstrip().splitlines()[0],
                    epilog=__doc__.lstrip().split('\n', 1)[1],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('suites', nargs='*', metavar='suite',
                        help='xie3dim, tracking, latency, bags (default: these four), '
                             'paper, integrity, driver')
    parser.add_argument('--methods', nargs='+', choices=list(METHODS),
                        help=f'default: {" ".join(DEFAULT_METHODS)} (paper: all)')
    parser.add_argument('--trials', type=int, default=200, help='xie3dim trials')
    parser.add_argument('--seconds', type=float, default=60.0,
                        help='tracking duration; integrity: seconds per stream')
    parser.add_argument('--latency-seconds', type=float, default=5.0,
                        help='latency: seconds per rate')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--seeds', type=integer(1, 1000), default=2,
                        help='field: runs per case; calibration: pumps (default 2)')
    parser.add_argument('--option', type=parse_option, action='append', default=[],
                        metavar='KEY=VALUE', help='estimator option, repeatable')
    parser.add_argument('--json', action='store_true', help='also print the reports as JSON')
    parser.add_argument('--runs', type=int, default=3000,
                        help='paper: Monte-Carlo runs per point (default 3000, as the paper)')
    parser.add_argument('--out', type=Path, default=Path('epp_bench_paper'),
                        help='paper: folder for paper.md, paper.json and the plots')
    parser.add_argument('--frames', type=integer(2, 10 ** 9), default=1_000_000,
                        help='soak: frames in-process (default 1,000,000)')
    parser.add_argument('--live-frames', type=integer(0, 10 ** 7), default=100_000,
                        help='soak: frames through the live node (default 100,000; 0: none)')
    parser.add_argument('--inputs', type=integer(1, 10 ** 9), default=100_000,
                        help='fuzz: inputs per protocol and per configuration field')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    default = ['xie3dim', 'tracking', 'latency', 'bags']
    known = default + ['paper', 'integrity', 'driver', 'soak', 'fuzz', 'field', 'calibration']
    suites = args.suites or default
    unknown = sorted(set(suites) - set(known))
    if unknown:
        parser.error(f'unknown suite(s) {unknown}; choose from {", ".join(known)}')
    options = dict(args.option)
    if options and {'latency', 'bags'} & set(suites):
        parser.error('--option applies to the in-process suites (xie3dim, tracking); the '
                     'node suites run posture_estimator with its parameters')
    methods = args.methods or DEFAULT_METHODS
    if 'tpsm' in methods and set(suites) - {'tracking', 'paper'}:
        parser.error('tpsm needs angle sensors, which only the tracking and paper suites '
                     'simulate')
    if args.runs < 1:
        parser.error('--runs must be >= 1')
    reports = []
    for suite in suites:
        if suite == 'paper':
            from epp_ros.tools import paper
            print(paper.run(args.out, args.runs, args.seed, args.methods, args.seconds),
                  flush=True)
            print(f'written to {args.out}/')
            continue
        if suite == 'xie3dim':
            reports.append(xie3dim_suite(methods, args.trials, args.seed, options))
        elif suite == 'tracking':
            reports.append(tracking_suite(methods, args.seconds, args.seed, options))
        elif suite == 'latency':
            reports.append(latency_suite(methods, args.latency_seconds, args.seed))
        elif suite == 'integrity':
            from epp_ros.tools import integrity_bench
            reports.append(integrity_bench.run(methods, args.seconds, args.seed, options))
        elif suite == 'driver':
            from epp_ros.tools.driver_bench import run_driver_bench
            reports.append({'suite': 'driver', 'rows': run_driver_bench()})
        elif suite == 'soak':
            from epp_ros.tools import soak_bench
            reports.append(soak_bench.run(args.frames, args.live_frames,
                                          (args.methods or ['chain'])[0], args.seed,
                                          progress=lambda text: print(text, flush=True)))
        elif suite == 'field':
            from epp_ros.tools import field_bench
            reports.append(field_bench.run(args.seconds, args.seeds, args.seed, args.trials))
        elif suite == 'calibration':
            from epp_ros.tools import calibration_bench
            reports.append(calibration_bench.run(args.seconds, args.seeds, args.seed))
        elif suite == 'fuzz':
            from epp_ros.tools import fuzz_bench
            reports.append(fuzz_bench.run(args.inputs, args.seed,
                                          progress=lambda text: print(text, flush=True)))
        else:
            reports.append(bags_suite(methods, args.seed))
        print(markdown(reports[-1]) + '\n', flush=True)
    print(f'commit {commit()}, Python {sys.version.split()[0]}, numpy {np.__version__}'
          + (f', options {options}' if options else ''))
    if args.json:       # the soak's headline figures at the top level of the last line
        summaries = [r['summary'] for r in reports if r['suite'] == 'soak']
        print(json.dumps({'commit': commit(), 'reports': reports,
                          **(summaries[-1] if summaries else {})}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
