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
The benchmarks' reports as text and files: markdown, JSON and plots, chosen by report type.

:func:`markdown` formats any suite's report: those of :mod:`epp_ros.tools.experiments`
here, those of the suites with a module of their own (integrity, field, soak, fuzz, driver,
calibration) by that module's ``markdown``, all listed in one table, :data:`MARKDOWN`.
:func:`to_json` gives a report's JSON object, :func:`write_paper` the paper's files.
"""
import dataclasses
import json
from pathlib import Path
import subprocess

from epp_ros.core.simulate import XIE3DIM
from epp_ros.tools import (calibration_bench, driver_bench, field_bench, fuzz_bench,
                           integrity_bench, soak_bench)
from epp_ros.tools.experiments import (BagsReport, LatencyReport, OTHER_POSTURE, PAPER_TABLE1,
                                       PAPER_TABLE3, PaperReport, PUBLISHED_NAMES, TABLE1_ETA,
                                       TrackingReport, Xie3dimReport)
import numpy as np


@dataclasses.dataclass
class CalibrationReport:
    """``calibration_bench.run``'s report (a dict), typed for :func:`markdown` as it is."""

    fields: dict


def commit():
    """Return the short hash of the checked-out commit, or 'unknown'."""
    try:
        return subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                              text=True, cwd=Path(__file__).resolve().parent,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


def _ratio(value, reference):
    return f'{value / reference:.2f}' if reference and np.isfinite(reference) else '-'


def _trials(count):
    return f'{count:,}'


# -- the method tables ----------------------------------------------------------------------
def _published_cell(figure):
    """Format a :class:`~epp_ros.tools.experiments.Published` figure, or '-'."""
    if figure is None:
        return '-'
    return f'{figure.mean_rmse_m} ({figure.name}); RMS {figure.rms_rmse_m}'


def method_table(rows):
    """
    Return the markdown lines of a table of :class:`~epp_ros.tools.experiments.MethodRow`.

    The published column is there when a row has a figure: the mean of the authors'
    per-trial RMSE over their trials, and its RMS.
    """
    published = any(row.published for row in rows)
    trials = next((row.published.trials for row in rows if row.published), 0)
    head = ('| method | RMSE, mean [m] | RMSE, RMS [m] | RMSE / CRLB (RMS) | mean arm-length '
            'error [m] | ms/frame p50 | p99 |')
    if published:
        head += f' published: mean RMSE of {_trials(trials)} trials [m], its RMS |'
    lines = [head, '|---' * (head.count('|') - 1) + '|']
    for row in rows:
        line = (f'| {row.method} | {row.mean_rmse_m:.3f} | {row.rmse_m:.3f} | '
                f'{_ratio(row.rmse_m, row.crlb_m)} | {max(row.arm_length_error_m):.1e} | '
                f'{row.ms_median:.2f} | {row.ms_p99:.2f} |')
        lines.append(line + (f' {_published_cell(row.published)} |' if published else ''))
    return lines


def published_xie3dim():
    """Return the lines naming every figure the authors published on xie3dim."""
    names = [PUBLISHED_NAMES[key] for key in XIE3DIM['published_mean_rmse_m']]
    means = ', '.join(f'{name} {value}' for name, value
                      in zip(names, XIE3DIM['published_mean_rmse_m'].values()))
    rms = ', '.join(f'{name} {value}' for name, value
                    in zip(names, XIE3DIM['published_rms_rmse_m'].values()))
    return [f'Published by the authors (their EMBED-SRLS code, sigma = '
            f'{XIE3DIM["published_sigma_m"]:g} m): the mean of the per-trial RMSE over '
            f'{_trials(XIE3DIM["published_trials"])} trials, {means} m; its RMS (their code '
            f'rerun), {rms} m.',
            "Their EMBED/CEPP is CEPP with its plane from the true posture, refined by Toh's "
            'post-processing (gradient descent on the unsquared stress after the '
            'embedding); their improved variant has no counterpart here.']


def xie3dim_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.Xie3dimReport`."""
    lines = [f"### xie3dim (authors' geometry), additive sigma = {report.sigma_m:g} m, "
             f'{report.trials} trials, cold start', '', *method_table(report.rows), '',
             f'Cramér–Rao bound of the chain model from the ranges (RMSE): '
             f'{report.crlb_m:.3f} m.']
    if report.truth_plane_slew_error_rad is not None:
        lines.append('The variants with the plane from the truth solved in the true plane: '
                     'largest |slew - true slew| '
                     f'{report.truth_plane_slew_error_rad:.1e} rad.')
    return '\n'.join(lines + [''] + published_xie3dim())


def tracking_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.TrackingReport`."""
    lines = [f'### truck pump, working cycle at 10 Hz, {report.frames} frames, sigma = '
             f'{report.sigma_m} m, {report.dropout:.0%} dropouts, warm start', '',
             *method_table(report.rows), '',
             f'Cramér–Rao bound of the chain model from the ranges (RMSE): '
             f'{report.crlb_m:.3f} m.']
    if report.fused_crlb_m is not None:
        lines.append('chain+angles also fuses the inclinometers and slew encoder that tpsm '
                     f'uses alone; its bound: {report.fused_crlb_m:.3f} m.')
    return '\n'.join(lines)


def latency_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.LatencyReport`."""
    lines = [f'### posture_estimator over DDS, uwb/ranges publish -> arm_posture receive '
             f'({report.seconds:g} s per rate)', '',
             '| method | 10 Hz p50 [ms] | p99 | lost | 100 Hz p50 [ms] | p99 | lost | '
             'sustained: none lost, all < 100 ms [frames/s] |',
             '|---|---|---|---|---|---|---|---|']
    lines += [f'| {row.method} | {row.p50_ms_10hz:.1f} | {row.p99_ms_10hz:.1f} | '
              f'{row.lost_10hz} | {row.p50_ms_100hz:.1f} | {row.p99_ms_100hz:.1f} | '
              f'{row.lost_100hz} | {row.sustained_hz:g} |' for row in report.rows]
    return '\n'.join(lines)


def bags_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.BagsReport`."""
    lines = [f'### A {report.frames}-frame bag: offline eval, and play --fast through '
             'the estimator node', '',
             '| method | eval [frames/s] | play --fast [frames/s] | frames lost |',
             '|---|---|---|---|']
    lines += [f'| {row.method} | {row.eval_fps:.0f} | {row.play_fps:.0f} | {row.lost} |'
              for row in report.rows]
    return '\n'.join(lines)


# -- the paper's parts ----------------------------------------------------------------------
def sweep_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.SweepReport` (part 1 of the paper)."""
    kind = report.kind
    methods = list(report.rows[0].methods)
    unit = '' if kind == 'eta' else ' [m]'
    lines = [f'### 1. RMSE [m] against {kind}{unit}, paper manipulator, {report.runs} runs '
             'per point, cold start; chain told the noise is Gaussian (nlos_fraction = 0). '
             'Each cell: the mean of the per-run RMSE (what the paper plots) / its RMS', '',
             f'| {kind} | ' + ' | '.join(methods) + ' | CRLB | chain RMS / CRLB |',
             '|---' * (len(methods) + 3) + '|']
    for row in report.rows:
        cells = [f'{row.methods[m].mean_rmse_m:.3f} / {row.methods[m].rmse_m:.3f}'
                 for m in methods]
        chain = row.methods['chain'].rmse_m if 'chain' in row.methods else np.nan
        lines.append(f'| {getattr(row, kind):g} | ' + ' | '.join(cells)
                     + f' | {row.crlb_m:.3f} | {_ratio(chain, row.crlb_m)} |')
    return '\n'.join(lines)


def table1_markdown(report):
    """Format Table 1 (arm-length errors, time) from the eta sweep's ``TABLE1_ETA`` row."""
    row = next(r for r in report.rows if np.isclose(r.eta, TABLE1_ETA))
    sdp = row.methods['sdp'].ms_median if 'sdp' in row.methods else None
    lines = [f'### 2. Table 1: absolute arm-length error [m] per section (base outward), '
             f"eta = {TABLE1_ETA}, {report.runs} runs; paper's values (as printed) in "
             'brackets', '',
             '| method | 1 | 2 | 3 | 4 | 5 | ms p50 (paper s) | SDP time / method time |',
             '|---|---|---|---|---|---|---|---|']
    for method, summary in row.methods.items():
        paper = PAPER_TABLE1.get(method)
        cells = [f'{ours:.3f}' + (f' ({theirs})' if paper else '') for ours, theirs in
                 zip(summary.arm_length_error_m, paper[0] if paper else [None] * 5)]
        cpu = f'{summary.ms_median:.2f}' + (f' ({paper[1]})' if paper else '')
        speed = f'{sdp / summary.ms_median:.1f}' if sdp else '-'
        lines.append(f'| {method} | ' + ' | '.join(cells) + f' | {cpu} | {speed} |')
    return '\n'.join(lines)


def nlos_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.NlosReport` (the paper's Table 3)."""
    sdp = report.methods['sdp'].ms_median if 'sdp' in report.methods else None
    lines = [f'### 3. Table 3: NLOS, truck pump, sigma = {report.sigma_m} m, '
             f'{report.nlos_fraction:.0%} of links with an exponential excess of mean '
             f'{report.gamma_m} m, TPSM: slew +-0.5 deg, inclinometers 0.5 deg; '
             f'{report.runs} random postures, cold start', '',
             "| method | RMSE, mean [m] (paper's mean) | RMSE, RMS [m] | RMS / LOS-only CRLB "
             '| ms p50 (paper s) | SDP time / method time |', '|---|---|---|---|---|---|']
    for method, summary in report.methods.items():
        paper = PAPER_TABLE3.get(method)
        mean = f'{summary.mean_rmse_m:.3f}' + (f' ({paper[0]})' if paper else '')
        cpu = f'{summary.ms_median:.2f}' + (f' ({paper[1]})' if paper else '')
        speed = f'{sdp / summary.ms_median:.1f}' if sdp else '-'
        lines.append(f'| {method} | {mean} | {summary.rmse_m:.3f} | '
                     f'{_ratio(summary.rmse_m, report.los_crlb_m)} | {cpu} | {speed} |')
    lines += ['', f'CRLB of the LOS links alone: {report.los_crlb_m:.3f} m.']
    return '\n'.join(lines)


def targets_markdown(report):
    """Format a :class:`~epp_ros.tools.experiments.TargetsReport` (part 6 of the paper)."""
    lines = [f'### 6. chain on truck pumps, sigma = {report.sigma_m} m, random postures, '
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
    lines += [f'| {row.sections} | {row.anchors} | {row.missing:.0%} | {row.runs} | '
              f'{row.rmse_m:.3f} | {row.local_fit_rmse_m:.3f} | {row.crlb_m:.3f} | '
              f'{_ratio(row.rmse_m, row.crlb_m)} | {row.search_misses} | '
              f'{row.other_posture_frames} | {_ratio(row.rmse_same_posture_m, row.crlb_m)} | '
              f'{row.ms_median:.2f} |' for row in report.rows]
    return '\n'.join(lines)


def _numbered(number, text):
    """Put a part's number into its heading: ``### title`` -> ``### 4. title``."""
    return f'### {number}. ' + text.lstrip('# ')


def paper_document(report):
    """Return paper.md: every part of a :class:`~epp_ros.tools.experiments.PaperReport`."""
    parts = report.reports
    sections = [sweep_markdown(parts.sweep_eta), '![RMSE vs eta](rmse_vs_eta.png)',
                sweep_markdown(parts.sweep_sigma), '![RMSE vs sigma](rmse_vs_sigma.png)',
                table1_markdown(parts.sweep_eta), nlos_markdown(parts.nlos),
                _numbered(4, xie3dim_markdown(parts.xie3dim)),
                _numbered(5, tracking_markdown(parts.tracking)),
                targets_markdown(parts.targets),
                f'commit {commit()}, {report.runs} runs per point, seed {report.seed}']
    return '\n\n'.join(sections) + '\n'


def paper_markdown(report):
    """Return paper.md and, when it was written, where."""
    return paper_document(report) + (f'\nwritten to {report.out}/' if report.out else '')


#: The formatter of each report type.
MARKDOWN = {
    Xie3dimReport: xie3dim_markdown,
    TrackingReport: tracking_markdown,
    LatencyReport: latency_markdown,
    BagsReport: bags_markdown,
    PaperReport: paper_markdown,
    integrity_bench.IntegrityReport: integrity_bench.markdown,
    field_bench.FieldReport: field_bench.markdown,
    soak_bench.SoakReport: soak_bench.markdown,
    fuzz_bench.FuzzReport: fuzz_bench.markdown,
    driver_bench.DriverReport: driver_bench.markdown,
    CalibrationReport: lambda report: calibration_bench.markdown(report.fields),
}


def markdown(report):
    """Format any suite's report by the formatter of its type (:data:`MARKDOWN`)."""
    try:
        formatter = MARKDOWN[type(report)]
    except KeyError:
        raise TypeError(f'no markdown for a {type(report).__name__}') from None
    return formatter(report)


# -- JSON and files -------------------------------------------------------------------------
def to_json(report):
    """Return a report's JSON object: its fields; paper.json's shape for the paper."""
    if isinstance(report, CalibrationReport):
        return report.fields
    if isinstance(report, PaperReport):
        return {'commit': commit(), 'runs': report.runs, 'seed': report.seed,
                'reports': dataclasses.asdict(report.reports)}
    return dataclasses.asdict(report)


def bench_json(reports):
    """
    Return the JSON line of ``epp_bench --json``: the commit and every report.

    The last soak's headline figures (its ``summary``) are also at the top level.
    """
    summaries = [report.summary for report in reports
                 if isinstance(report, soak_bench.SoakReport)]
    return json.dumps({'commit': commit(), 'reports': [to_json(r) for r in reports],
                       **(summaries[-1] if summaries else {})})


def plot_sweep(report, path):
    """Plot a sweep, log-log: the mean RMSE (the paper's figure); the RMS with the CRLB."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    levels = [getattr(row, report.kind) for row in report.rows]
    figure, panels = pyplot.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for axes, field, name in zip(panels, ('mean_rmse_m', 'rmse_m'), ('mean', 'RMS')):
        for method in report.rows[0].methods:
            axes.plot(levels, [getattr(row.methods[method], field) for row in report.rows],
                      marker='o', label=method)
        axes.set(xscale='log', yscale='log', ylabel=f'RMSE, {name} [m]',
                 xlabel=report.kind if report.kind == 'eta' else 'sigma [m]',
                 title=f'{name} of the per-run RMSE, {report.runs} runs per point')
        axes.grid(True, which='both', alpha=0.3)
    panels[1].plot(levels, [row.crlb_m for row in report.rows], 'k--', label='CRLB (chain)')
    panels[1].legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    pyplot.close(figure)


def write_paper(report, out):
    """Write paper.md, paper.json, rmse_vs_eta.png and rmse_vs_sigma.png into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'paper.md').write_text(paper_document(report))
    (out / 'paper.json').write_text(json.dumps(to_json(report), indent=1))
    plot_sweep(report.reports.sweep_eta, out / 'rmse_vs_eta.png')
    plot_sweep(report.reports.sweep_sigma, out / 'rmse_vs_sigma.png')
