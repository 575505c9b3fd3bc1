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
``epp_bench paper``: the seed paper's experiments, our figures next to its published ones.

1. RMSE against the noise, multiplicative eta (the paper's figure) and additive sigma, with
   the Cramér–Rao bound of the chain model; cold start every run.
2. Table 1: absolute arm-length error per section and CPU time (eta = 0.1, from part 1).
3. Table 3: NLOS ranges (sigma = 0.2 m, exponential excess of mean 2 m on 20 % of links)
   on the truck pump, random postures, against the bound of the LOS links alone.
4. The authors' xie3dim geometry at sigma = 1 m against their published single trial.
5. Tracking: a working cycle at 10 Hz, warm-started.
6. The chain estimator's targets: RMSE / CRLB on 4-6 sections, 4-6 anchors, 15 % missing.

The paper's geometry is not printed; its p = 5, 9/7/7/9/9 m manipulator is the authors'
xie3dim anchors and posture (``simulate.XIE3DIM``) with those exact lengths. The paper
gives neither the eta of Table 1, nor the NLOS fraction, nor TPSM's inclinometer noise;
ours are stated in each table.
"""
import json
from pathlib import Path
import time

from epp_ros.core import BoomModel, METHODS, PostureEstimator
from epp_ros.core.bounds import crlb
from epp_ros.core.chain import angles_from_joints, ChainMethod
from epp_ros.core.measurements import Measurements, Residuals
from epp_ros.core.metrics import pooled_rmse
from epp_ros.core.simulate import (AngleNoise, observe, random_posture, RangeNoise, truck_pump,
                                   xie3dim)
import numpy as np

from .bench import (commit, markdown, method_estimate, published_options, run_frames, summarize,
                    tracking_suite, xie3dim_suite)

#: Table 1 of the paper: absolute arm-length error per segment (as printed, its segment 1
#: may be the tip: it numbers points from the tip) and CPU seconds (MATLAB).
PAPER_TABLE1 = {'sdp': ([1.639, 1.623, 1.554, 1.540, 1.681], 0.286),
                'srls': ([2.215, 4.964, 5.780, 4.743, 5.024], 0.519),
                'epp1': ([1.630, 1.629, 1.554, 1.548, 1.692], 0.041),
                'epp2': ([0.057, 0.014, 0.015, 0.016, 0.017], 0.047)}
#: Table 3 (NLOS): RMSE metres and CPU seconds; the paper's "CEPP2" is our cepp.
PAPER_TABLE3 = {'sdp': (4.503, 0.312), 'srls': (5.464, 0.539), 'tpsm': (4.765, 0.019),
                'epp2': (4.249, 0.048), 'cepp': (2.533, 0.063)}
ETAS = (0.01, 0.02, 0.05, 0.1, 0.2)
SIGMAS = (0.1, 0.2, 0.5, 1.0, 2.0)
TABLE1_ETA = 0.1
SWEEP_METHODS = ['sdp', 'srls', 'epp1', 'epp2', 'cepp', 'chain']
#: The chain's NLOS prior where the simulated noise is Gaussian.
GAUSSIAN = 0.0
NLOS_METHODS = ['sdp', 'srls', 'tpsm', 'epp2', 'cepp', 'chain']


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
    return {m: PostureEstimator(model, m, **published_options(m, options.get(m, {})))
            for m in methods}


def noise_sweep(kind, levels, runs, methods, seed):
    """
    RMSE of each method at each noise level, cold start per run, and the CRLB.

    ``kind`` is ``'eta'`` (range * (1 + eta N)) or ``'sigma'`` (range + sigma N).
    """
    model, slew, pitches = paper_manipulator()
    joints = model.forward_kinematics(slew, pitches)
    truth = model.ranges(joints)
    rows = []
    for level in levels:
        rng = np.random.default_rng([seed, int(level * 1e6)])
        noise = RangeNoise(eta=level) if kind == 'eta' else RangeNoise(sigma=level)
        frames = [noise.apply(truth, rng)[0] for _ in range(runs)]
        # The chain is told the noise model, Gaussian here, as every method is told sigma.
        chain = {'sigma': 1e-3, 'eta': level} if kind == 'eta' else {'sigma': level}
        chain['nlos_fraction'] = GAUSSIAN
        estimators = _estimators(model, methods, {'chain': chain})
        sigma = level * truth if kind == 'eta' else level
        row = {kind: level, 'crlb_m': crlb(model, slew, pitches, sigma).rmse, 'methods': {}}
        for method, estimator in estimators.items():
            row['methods'][method] = summarize(*run_frames(estimator, frames,
                                                           [joints] * runs, cold=True))
        rows.append(row)
    return {'part': f'sweep_{kind}', 'runs': runs, 'rows': rows}


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
    rows = {method: summarize(*run_frames(estimator, frames, postures, cold=True))
            for method, estimator in estimators.items()}
    return {'part': 'nlos', 'runs': runs, 'sigma_m': sigma, 'nlos_fraction': fraction,
            'gamma_m': gamma, 'los_crlb_m': pooled_rmse(bounds), 'methods': rows}


#: Distance at some joint beyond which a fit is another posture, not noise about one, m.
OTHER_POSTURE = 0.5


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
    lengths = {4: (10.0, 8.0, 9.0, 9.0), 5: (9.0, 7.0, 7.0, 9.0, 9.0),
               6: (8.0, 7.0, 6.0, 7.0, 6.0, 6.0)}
    rows = []
    for p, arm_lengths in lengths.items():
        for m in (4, 5, 6):
            model = truck_pump(arm_lengths, n_anchors=m)
            for dropout in (0.0, 0.15):
                rng = np.random.default_rng([seed, p, m, int(dropout * 100)])
                estimator = PostureEstimator(model, 'chain', sigma=sigma,
                                             nlos_fraction=GAUSSIAN)
                reference = ChainMethod(model, sigma=sigma, nlos_fraction=GAUSSIAN)
                squared, local, bounds, times, other = [], [], [], [], []
                misses = 0
                for _ in range(runs):
                    slew, pitches, joints = random_posture(model, rng)
                    frame, _ = observe(model, slew, pitches, rng,
                                       RangeNoise(sigma=sigma, dropout=dropout))
                    measured = np.isfinite(frame['ranges'])
                    bound = crlb(model, slew, pitches, sigma, measured).rmse
                    if not np.isfinite(bound):
                        continue        # the links do not determine the posture
                    estimator.reset()
                    start = time.perf_counter()
                    estimate = method_estimate(estimator, frame)
                    times.append(time.perf_counter() - start)
                    residuals = Residuals(model, Measurements.ranges_only(frame['ranges']),
                                          reference.noise)
                    near, near_cost, _, _ = reference.fit(np.r_[slew, pitches], residuals)
                    found = np.r_[estimator.last_diagnostics['slew'],
                                  estimator.last_diagnostics['pitches']]
                    misses += near_cost < reference.cost(found, residuals) - 1e-3
                    squared.append(np.mean(np.sum((estimate - joints) ** 2, axis=1)))
                    near_joints = model.forward_kinematics(near[0], near[1:])
                    local.append(np.mean(np.sum((near_joints - joints) ** 2, axis=1)))
                    other.append(np.linalg.norm(estimate - near_joints, axis=1).max()
                                 > OTHER_POSTURE)
                    bounds.append(bound)
                rows.append({'sections': p, 'anchors': m, 'missing': dropout,
                             'runs': len(squared), 'rmse_m': float(np.sqrt(np.mean(squared))),
                             'local_fit_rmse_m': float(np.sqrt(np.mean(local))),
                             'search_misses': int(misses), 'crlb_m': pooled_rmse(bounds),
                             'other_posture_frames': int(np.sum(other)),
                             'rmse_same_posture_m': pooled_rmse(
                                 np.sqrt(np.asarray(squared)[~np.asarray(other, bool)])),
                             'ms_median': 1e3 * float(np.median(times))})
    return {'part': 'targets', 'sigma_m': sigma, 'rows': rows}


# -- output -------------------------------------------------------------------------------
def _ratio(value, reference):
    return f'{value / reference:.2f}' if reference and np.isfinite(reference) else '-'


def sweep_markdown(report):
    kind = report['part'].split('_')[1]
    methods = list(report['rows'][0]['methods'])
    unit = '' if kind == 'eta' else ' [m]'
    lines = [f'### 1. RMSE [m] against {kind}{unit}, paper manipulator, {report["runs"]} runs '
             'per point, cold start; chain told the noise is Gaussian (nlos_fraction = 0)', '',
             f'| {kind} | ' + ' | '.join(methods) + ' | CRLB | chain / CRLB |',
             '|---' * (len(methods) + 3) + '|']
    for row in report['rows']:
        values = [row['methods'][m]['rmse_m'] for m in methods]
        chain = row['methods'].get('chain', {}).get('rmse_m', np.nan)
        lines.append(f'| {row[kind]:g} | ' + ' | '.join(f'{v:.3f}' for v in values)
                     + f' | {row["crlb_m"]:.3f} | {_ratio(chain, row["crlb_m"])} |')
    return '\n'.join(lines)


def table1_markdown(report):
    row = next(r for r in report['rows'] if np.isclose(r['eta'], TABLE1_ETA))
    sdp = row['methods'].get('sdp', {}).get('ms_median')
    lines = [f'### 2. Table 1: absolute arm-length error [m] per section (base outward), '
             f'eta = {TABLE1_ETA}, {report["runs"]} runs; paper\'s values (as printed) in '
             'brackets', '',
             '| method | 1 | 2 | 3 | 4 | 5 | ms p50 (paper s) | SDP time / method time |',
             '|---|---|---|---|---|---|---|---|']
    for method, summary in row['methods'].items():
        paper = PAPER_TABLE1.get(method)
        cells = [f'{ours:.3f}' + (f' ({theirs})' if paper else '') for ours, theirs in
                 zip(summary['arm_length_error_m'], paper[0] if paper else [None] * 5)]
        cpu = f'{summary["ms_median"]:.2f}' + (f' ({paper[1]})' if paper else '')
        speed = f'{sdp / summary["ms_median"]:.1f}' if sdp else '-'
        lines.append(f'| {method} | ' + ' | '.join(cells) + f' | {cpu} | {speed} |')
    return '\n'.join(lines)


def nlos_markdown(report):
    sdp = report['methods'].get('sdp', {}).get('ms_median')
    lines = [f'### 3. Table 3: NLOS, truck pump, sigma = {report["sigma_m"]} m, '
             f'{report["nlos_fraction"]:.0%} of links with an exponential excess of mean '
             f'{report["gamma_m"]} m, TPSM: slew +-0.5 deg, inclinometers 0.5 deg; '
             f'{report["runs"]} random postures, cold start', '',
             '| method | RMSE [m] (paper) | RMSE / LOS-only CRLB | ms p50 (paper s) | '
             'SDP time / method time |', '|---|---|---|---|---|']
    for method, summary in report['methods'].items():
        paper = PAPER_TABLE3.get(method)
        rmse = f'{summary["rmse_m"]:.3f}' + (f' ({paper[0]})' if paper else '')
        cpu = f'{summary["ms_median"]:.2f}' + (f' ({paper[1]})' if paper else '')
        speed = f'{sdp / summary["ms_median"]:.1f}' if sdp else '-'
        lines.append(f'| {method} | {rmse} | {_ratio(summary["rmse_m"], report["los_crlb_m"])}'
                     f' | {cpu} | {speed} |')
    lines += ['', f'CRLB of the LOS links alone: {report["los_crlb_m"]:.3f} m.']
    return '\n'.join(lines)


def targets_markdown(report):
    lines = [f'### 6. chain on truck pumps, sigma = {report["sigma_m"]} m, random postures, '
             'cold start, chain told the noise is Gaussian (nlos_fraction = 0) '
             '(target: RMSE <= 1.05 CRLB)', '',
             '"fit from the truth": the same least squares started at the true angles, the '
             'fit the local CRLB describes; "misses": frames where it ends with a lower cost '
             '(by more than 0.001; the loss is half a chi-square) than the cold start; '
             f'"other posture": frames where the cold start ends more than {OTHER_POSTURE} m '
             'from that fit at some joint, with a lower cost (another posture explains the '
             'ranges better); "RMSE, same posture": over the other frames.', '',
             '| sections | anchors | missing | runs | RMSE [m] | fit from the truth [m] | '
             'CRLB [m] | RMSE / CRLB | misses | other posture | RMSE, same posture / CRLB | '
             'ms p50 |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for row in report['rows']:
        lines.append(f'| {row["sections"]} | {row["anchors"]} | {row["missing"]:.0%} | '
                     f'{row["runs"]} | {row["rmse_m"]:.3f} | {row["local_fit_rmse_m"]:.3f} | '
                     f'{row["crlb_m"]:.3f} | {_ratio(row["rmse_m"], row["crlb_m"])} | '
                     f'{row["search_misses"]} | {row["other_posture_frames"]} | '
                     f'{_ratio(row["rmse_same_posture_m"], row["crlb_m"])} | '
                     f'{row["ms_median"]:.2f} |')
    return '\n'.join(lines)


def plot_sweep(report, path):
    """RMSE against noise, one line per method and the CRLB dashed, log-log."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    kind = report['part'].split('_')[1]
    levels = [row[kind] for row in report['rows']]
    figure, axes = pyplot.subplots(figsize=(6, 4.2))
    for method in report['rows'][0]['methods']:
        axes.plot(levels, [row['methods'][method]['rmse_m'] for row in report['rows']],
                  marker='o', label=method)
    axes.plot(levels, [row['crlb_m'] for row in report['rows']], 'k--', label='CRLB (chain)')
    axes.set(xscale='log', yscale='log', xlabel=kind if kind == 'eta' else 'sigma [m]',
             ylabel='RMSE [m]', title=f'RMSE vs {kind}, {report["runs"]} runs per point')
    axes.grid(True, which='both', alpha=0.3)
    axes.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    pyplot.close(figure)


def run(out, runs, seed, methods=None, tracking_seconds=60.0, target_runs=None):
    """
    All parts; writes paper.md, paper.json and the PNG plots into ``out``.

    Returns the markdown.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    methods = methods or list(METHODS)
    sweep = [m for m in SWEEP_METHODS if m in methods]
    reports = {'sweep_eta': noise_sweep('eta', ETAS, runs, sweep, seed),
               'sweep_sigma': noise_sweep('sigma', SIGMAS, runs, sweep, seed),
               'nlos': nlos_table(runs, [m for m in NLOS_METHODS if m in methods], seed),
               'xie3dim': xie3dim_suite([m for m in methods if m != 'tpsm'], runs, seed, {}),
               'tracking': tracking_suite(methods, tracking_seconds, seed, {}),
               'targets': target_cases(target_runs or min(runs, 300), seed)}
    parts = [sweep_markdown(reports['sweep_eta']), '![RMSE vs eta](rmse_vs_eta.png)',
             sweep_markdown(reports['sweep_sigma']), '![RMSE vs sigma](rmse_vs_sigma.png)',
             table1_markdown(reports['sweep_eta']), nlos_markdown(reports['nlos']),
             '### 4. ' + markdown(reports['xie3dim']).lstrip('# '),
             '### 5. ' + markdown(reports['tracking']).lstrip('# '),
             targets_markdown(reports['targets'])]
    stamp = f'commit {commit()}, {runs} runs per point, seed {seed}'
    text = '\n\n'.join(parts + [stamp]) + '\n'
    (out / 'paper.md').write_text(text)
    (out / 'paper.json').write_text(json.dumps({'commit': commit(), 'runs': runs,
                                                'seed': seed, 'reports': reports}, indent=1))
    plot_sweep(reports['sweep_eta'], out / 'rmse_vs_eta.png')
    plot_sweep(reports['sweep_sigma'], out / 'rmse_vs_sigma.png')
    return text
