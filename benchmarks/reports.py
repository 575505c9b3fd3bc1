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

:func:`markdown` formats any suite's report by its type, all listed in one table,
:data:`MARKDOWN`: those of :mod:`benchmarks.experiments` and of the suites with a module of
their own (integrity, field, soak, fuzz, driver) here; calibration's by
``calibration_bench.markdown``. The suites' modules hold what is run and their typed reports,
and do not import this one (but ``python -m benchmarks.driver_bench``, when it prints
:func:`driver_table`).
:func:`to_json` gives a report's JSON object, :func:`write_paper` the paper's files.
"""
import dataclasses
import json
import math
from pathlib import Path
import subprocess

from benchmarks import (calibration_bench, compare_bench, driver_bench, field_bench,
                        fuzz_bench, integrity_bench, soak_bench, speed_bench)
from benchmarks.experiments import (BagsReport, ControllerReport, LatencyReport,
                                    OTHER_POSTURE, PAPER_TABLE1, PAPER_TABLE3, PaperReport,
                                    PUBLISHED_NAMES, TABLE1_ETA, TrackingReport, Xie3dimReport)
from epp_ros.core.simulation import XIE3DIM
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
    """Format a :class:`~benchmarks.experiments.Published` figure, or '-'."""
    if figure is None:
        return '-'
    return f'{figure.mean_rmse_m} ({figure.name}); RMS {figure.rms_rmse_m}'


def method_table(rows):
    """
    Return the markdown lines of a table of :class:`~benchmarks.experiments.MethodRow`.

    The published column is there when a row has a figure: the mean of the authors'
    per-trial RMSE over their trials, and its RMS.
    """
    published = any(row.published for row in rows)
    trials = next((row.published.trials for row in rows if row.published), 0)
    head = ('| method | RMSE, mean [m] | RMSE, RMS [m] | RMSE / CRLB (RMS) | valid: RMSE / '
            'CRLB | published | valid > 1 m off / confidently | mean arm-length error [m] | '
            'ms/frame p50 | p99 |')
    if published:
        head += f' published: mean RMSE of {_trials(trials)} trials [m], its RMS |'
    lines = [head, '|---' * (head.count('|') - 1) + '|']
    for row in rows:
        line = (f'| {row.method} | {row.mean_rmse_m:.3f} | {row.rmse_m:.3f} | '
                f'{_ratio(row.rmse_m, row.crlb_m)} | {_valid_cells(row)} | '
                f'{max(row.arm_length_error_m):.1e} | {row.ms_median:.2f} | {row.ms_p99:.2f} |')
        lines.append(line + (f' {_published_cell(row.published)} |' if published else ''))
    return lines


def _valid_cells(row):
    """Return the cells of what a user gets of a row: '-' where its frames are not judged."""
    if row.published_fraction is None:
        return '- | - | -'
    ratio = _ratio(row.valid_rmse_m, row.crlb_m) if row.published_fraction else '-'
    return (f'{ratio} | {row.published_fraction:.0%} | '
            f'{row.wrong_valid} / {row.confidently_wrong}')


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
    """Format a :class:`~benchmarks.experiments.Xie3dimReport`."""
    lines = [f"### xie3dim (authors' geometry), additive sigma = {report.sigma_m:g} m, "
             f'{report.trials} trials, cold start', '', *method_table(report.rows), '',
             f'Cramér–Rao bound of the chain model from the ranges (RMSE): '
             f'{report.crlb_m:.3f} m.']
    if report.truth_plane_slew_error_rad is not None:
        lines.append('The variants with the plane from the truth solved in the true plane: '
                     'largest |slew - true slew| '
                     f'{report.truth_plane_slew_error_rad:.1e} rad.')
    return '\n'.join(lines + [''] + published_xie3dim() + ambiguity_table(report.ambiguity))


def ambiguity_table(rows):
    """Return the xie3dim suite's ambiguity sweep as lines of markdown (none without rows)."""
    if not rows:
        return []
    return ['', 'What the frames decide: each method with its defaults (cepp: the field CEPP), '
            'told sigma, at each ambiguity_odds (the default 1000): a rival posture that '
            'many times less likely than the estimate, or likelier, makes the frame '
            'ambiguous.', '',
            '| method | ambiguity_odds | published | valid: RMSE / CRLB | '
            'valid > 1 m off / confidently |', '|---|---|---|---|---|',
            *(f'| {row.method} | {row.odds:g} | {row.published_fraction:.0%} | '
              f'{row.valid_ratio:.2f} | {row.wrong_valid} / {row.confidently_wrong} |'
              for row in rows)]


def tracking_markdown(report):
    """Format a :class:`~benchmarks.experiments.TrackingReport`."""
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
    """Format a :class:`~benchmarks.experiments.LatencyReport`."""
    lines = [f'### posture_estimator over DDS, uwb/ranges publish -> arm_posture receive '
             f'({report.seconds:g} s per rate)', '',
             '| method | 10 Hz p50 [ms] | p99 | unanswered | 100 Hz p50 [ms] | p99 | '
             'unanswered | sustained: all answered, < 100 ms [frames/s] |',
             '|---|---|---|---|---|---|---|---|']
    lines += [f'| {row.method} | {row.p50_ms_10hz:.1f} | {row.p99_ms_10hz:.1f} | '
              f'{row.lost_10hz} | {row.p50_ms_100hz:.1f} | {row.p99_ms_100hz:.1f} | '
              f'{row.lost_100hz} | {row.sustained_hz:g} |' for row in report.rows]
    lines += ['', 'set_parameters twice a second (valid values, node_bench.LIVE_CHANGES) '
              'while frames flow at 10 Hz:', '',
              '| method | response p99 [ms] | max | frames p99 [ms] | frames unanswered + '
              'calls lost |',
              '|---|---|---|---|---|']
    lines += [f'| {row.method} | {row.parameter_p99_ms:.1f} | {row.parameter_max_ms:.1f} | '
              f'{row.parameter_frames_p99_ms:.1f} | {row.parameter_lost} |'
              for row in report.rows]
    lines += ['', 'Unanswered: no arm_posture for the frame, refused (not published) or lost.']
    return '\n'.join(lines)


def controller_markdown(report):
    """Format a :class:`~benchmarks.experiments.ControllerReport`."""
    lines = [f'### posture_estimator on one core shared with a busy process, 10 Hz for '
             f'{report.seconds:g} s: uwb/ranges publish -> arm_posture receive', '',
             '| method | frames | p50 [ms] | p90 | p99 | max | unanswered | the node: '
             'received, refused |', '|---|---|---|---|---|---|---|---|']
    lines += [f'| {row.method} | {row.frames} | {row.p50_ms:.1f} | {row.p90_ms:.1f} | '
              f'{row.p99_ms:.1f} | {row.max_ms:.1f} | {row.unanswered} | {row.received}, '
              f'{row.refused} |' for row in report.rows]
    lines += ['', 'Unanswered: no posture within 3 s of the last frame; refused frames '
              'publish none and count here too. The counts of the node (its /diagnostics, the '
              '10 warm-up frames included; -1: no report came) tell them apart.']
    return '\n'.join(lines)


def bags_markdown(report):
    """Format a :class:`~benchmarks.experiments.BagsReport`."""
    lines = [f'### A {report.frames}-frame bag: offline eval, and play --fast through '
             'the estimator node', '',
             '| method | eval [frames/s] | play --fast [frames/s] | frames lost |',
             '|---|---|---|---|']
    lines += [f'| {row.method} | {row.eval_fps:.0f} | {row.play_fps:.0f} | {row.lost} |'
              for row in report.rows]
    return '\n'.join(lines)


# -- the paper's parts ----------------------------------------------------------------------
def sweep_markdown(report):
    """Format a :class:`~benchmarks.experiments.SweepReport` (part 1 of the paper)."""
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
    """Format a :class:`~benchmarks.experiments.NlosReport` (the paper's Table 3)."""
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
    """Format a :class:`~benchmarks.experiments.TargetsReport` (part 6 of the paper)."""
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
    """Return paper.md: every part of a :class:`~benchmarks.experiments.PaperReport`."""
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


# -- the suites with a module of their own --------------------------------------------------
def _finite(value):
    """Return ``value``, or None where it is NaN (a ratio over no frames)."""
    return None if value is None or not math.isfinite(value) else value


def _or_dash(value, spec='.1f', unit=''):
    """Format a figure that may be missing (None: '-')."""
    return '-' if value is None else f'{value:{spec}}{unit}'


def _integrity_case_cell(row):
    """Format ``valid % / wrong and valid / worst recovery`` of one method on one case."""
    cell = f'{100.0 * row["valid"] / max(row["frames"], 1):.1f} % / {row["wrong_valid"]}'
    if row['events']:
        times = row['recoveries_s']
        recovered = [t for t in times if t is not None]
        cell += ' / ' + ('never' if len(recovered) < len(times)
                         else _or_dash(max(recovered)))
    return cell


def _integrity_method_table(rows):
    """Return the lines of the per-method table: the suite's targets."""
    lines = ['| method | wrong & valid [frames] | recovery worst [s] | median [s] | '
             'not recovered | false rejections: clean stream | broken streams | '
             'ms/frame p50 | p99 |', '|---|---|---|---|---|---|---|---|---|']
    lines += [f'| {row["method"]} | {row["wrong_valid"]} of {row["frames"]} | '
              f'{_or_dash(row["recovery_worst_s"])} | {_or_dash(row["recovery_median_s"])} | '
              f'{row["unrecovered"]} of {row["events"]} | '
              f'{row["false_rejection_clean"]:.2%} ({row["clean_rejected"]}/'
              f'{row["clean_scored"]}) | {row["false_rejection_broken"]:.2%} '
              f'({row["broken_rejected"]}/{row["broken_scored"]}) | '
              f'{row["ms_median"]:.2f} | {row["ms_p99"]:.2f} |' for row in rows]
    return lines


def _integrity_case_table(report):
    """Return the lines of the per-case table, a column per method."""
    methods = [row['method'] for row in report.rows]
    lines = ['| case | frames | ' + ' | '.join(methods) + ' |',
             '|---|---|' + '---|' * len(methods)]
    cells = {(row['method'], row['case']): row for row in report.case_rows}
    for case, description in report.cases.items():
        frames = cells[methods[0], case]['frames'] if methods else 0
        lines.append(f'| {case}: {description} | {frames} | '
                     + ' | '.join(_integrity_case_cell(cells[method, case])
                                  for method in methods) + ' |')
    return lines


def _index_runs(indices, most=12):
    """``[3, 4, 5, 9]`` -> ``'3-5, 9'``; after ``most`` runs, ``', ...'``."""
    runs = []
    for index in indices:
        if runs and index == runs[-1][1] + 1:
            runs[-1][1] = index
        else:
            runs.append([index, index])
    text = ', '.join(str(a) if a == b else f'{a}-{b}' for a, b in runs[:most])
    return text + (', ...' if len(runs) > most else '')


def _wrong_valid_bullet(row, first):
    """Return the bullet of a method on a case with wrong-and-valid frames, and the first."""
    joints = ', '.join(f'{k} {error:.2f} m (joint_std {std:.3f})' for k, error, std
                       in zip(first['joints'], first['errors_m'], first['joint_std_m']))
    return (f'- {row["method"]} {row["case"]}: {row["wrong_valid"]} frames '
            f'({_index_runs(row["wrong_indices"])}); frame {first["frame"]} '
            f'({first["stamp_s"]:.1f} s): joints {joints}; {first["status"]}: '
            f'{first["message"]}')


def _wrong_valid_lines(report):
    """Return the bullets of the wrong-and-valid frames, none when there are none."""
    firsts = {}
    for detail in report.wrong_frames:
        firsts.setdefault((detail['method'], detail['case']), detail)
    wrong = [row for row in report.case_rows if row['wrong_valid']]
    if not wrong:
        return []
    return ['', 'Wrong and valid (the first of each method and case):'] + [
        _wrong_valid_bullet(row, firsts[row['method'], row['case']]) for row in wrong]


def _slow_recovery_lines(report):
    """Return the bullets of the recoveries over the target, none when there are none."""
    if not report.slow_recoveries:
        return []
    target = integrity_bench.RECOVERY_TARGET_S
    lines = ['', f'Recoveries over {target:g} s:']
    for d in report.slow_recoveries:
        took = ('not recovered before the next' if d['recovery_s'] is None
                else f'{d["recovery_s"]:.1f} s')
        lines.append(f'- {d["method"]} {d["case"]} frame {d["frame"]} ({d["label"]}): {took}'
                     f'; the next {target:g} s: {d["statuses_after"]}')
    return lines


def _clean_rejection_lines(report):
    """Return the line of the clean stream's rejections by status, none when there are none."""
    why = {row['method']: row['rejected_statuses'] for row in report.case_rows
           if row['case'] == 'clean' and row['rejected']}
    if not why:
        return []
    return ['', 'Clean-stream frames rejected, by status: ' + '; '.join(
        f'{method} ' + ', '.join(f'{status} {count}' for status, count in counts.items())
        for method, counts in why.items()) + '.']


def _integrity_targets():
    """Return the line stating the integrity suite's targets."""
    return (f'Targets: no frame valid with a joint > {integrity_bench.WRONG_METRES:g} m and > '
            f'{integrity_bench.WRONG_SIGMAS:g} predicted sigma off; recovery <= '
            f'{integrity_bench.RECOVERY_TARGET_S:g} s; false rejections <= '
            f'{integrity_bench.FALSE_REJECTION_TARGET:.1%}.')


def integrity_markdown(report):
    """
    Format an :class:`~benchmarks.integrity_bench.IntegrityReport`.

    Per-method targets, the per-case table, then the frames that miss a target.
    """
    lines = [f'### Integrity: truck pump, working cycle at 10 Hz, sigma = {report.sigma_m} '
             f'm, {report.dropout:.0%} dropouts, {report.seconds:g} s per stream, '
             f'seed {report.seed}', '', *_integrity_method_table(report.rows), '',
             _integrity_targets(), '', *_integrity_case_table(report), '',
             'Cells: frames valid / wrong and valid / worst recovery [s] (broken '
             'streams; "never": a run not recovered before the next).']
    lines += _wrong_valid_lines(report) + _slow_recovery_lines(report)
    return '\n'.join(lines + _clean_rejection_lines(report))


def _field_cell(row, method):
    """Format a method's ratio in a case: '(!)' when over its target, and its gross frames."""
    target = field_bench.TARGETS.get(method)
    over = (target is not None and row['case'] not in field_bench.CALIBRATION
            and row[method]['ratio'] > target)
    gross = row[method]['gross']
    return (f'{row[method]["ratio"]:.2f}' + (' (!)' if over else '')
            + (f' [{gross} gross]' if gross else ''))


def _field_table(rows):
    """Return the lines of the table of every case: each method's ratio, and how often valid."""
    methods = field_bench.METHODS
    lines = ['| case | CRLB [m] | ' + ' | '.join(methods) + ' | valid (chain / cepp / track) |',
             '|---|---|' + '---|' * len(methods) + '---|']
    for row in rows:
        valid = ' / '.join(f'{100 * row[m]["valid"]:.0f} %' for m in ('chain', 'cepp', 'track'))
        lines.append(f'| {row["case"]} | {row["bound_m"]:.3f} | '
                     + ' | '.join(_field_cell(row, method) for method in methods)
                     + f' | {valid} |')
    return lines


def _field_published_table(rows):
    """
    Return the lines of the table of what each method published as valid.

    Per method: the ratio over those frames, the fraction published, the frames published
    while more than 1 m off and, of those, the ones whose predicted RMSE was under a third
    of their error (confidently wrong).
    """
    methods = field_bench.METHODS

    def cell(figures):          # no frame published: no ratio
        return (f'{_or_dash(_finite(figures["published_ratio"]), ".2f")} '
                f'({100 * figures["valid"]:.0f} %; {figures["wrong_valid"]} / '
                f'{figures["confidently_wrong"]})')
    return ['| case | ' + ' | '.join(methods) + ' |', '|---|' + '---|' * len(methods)] + [
        f'| {row["case"]} | ' + ' | '.join(cell(row[m]) for m in methods) + ' |' for row in rows]


def _field_information_table(rows):
    """
    Return the lines of the table of what the frames' information allows.

    Per method: the frames refused as ambiguous that the truth's own ranges decide
    (``field_bench.truth_decides``), and the published share of the frames allowed.
    """
    methods = field_bench.METHODS
    return ['| case | ' + ' | '.join(methods) + ' |', '|---|' + '---|' * len(methods)] + [
        f'| {row["case"]} | ' + ' | '.join(
            f'{100 * row[m]["allowed_share"]:.0f} % ({row[m]["decidable"]})' for m in methods)
        + ' |' for row in rows]


def _field_heard_lines(rows):
    """Return a line per case with a tag unheard: the ratios over the frames with every tag."""
    # with a silent tag, no single frame determines its joint
    return [f'{row["case"]}: on the {100 * row["heard"]:.0f} % of frames with every tag '
            'heard, ' + ', '.join(f'{m} {row[m]["heard_ratio"]:.2f}'
                                  for m in field_bench.METHODS) + '.'
            for row in rows if row['heard'] < 1.0]


def _field_authors_table(authors):
    """Return the lines of the table of the authors' geometry, a new estimator per frame."""
    return ["| authors' geometry, new estimator per frame | CRLB [m] | chain | cepp |",
            '|---|---|---|---|'] + [
        f'| sigma {row["sigma_m"]:g} m | {row["bound_m"]:.3f} | '
        + ' | '.join(f'{row[m]["ratio"]:.2f} ({row[m]["gross"]} gross)'
                     for m in ('chain', 'cepp')) + ' |' for row in authors]


def field_markdown(report):
    """Format a :class:`~benchmarks.field_bench.FieldReport`: the README's tables."""
    targets, posterior, cost = field_bench.TARGETS, report.posterior, report.cost
    lines = [f'### Field effects, defaults: RMSE / clean line-of-sight CRLB at the true noise '
             f'({report.seeds} x {report.seconds:g} s per case at {field_bench.RATE:g} Hz, '
             f'first {field_bench.WARM_UP_S:g} s not scored)', '', *_field_table(report.rows),
             '', f'Targets: chain <= {targets["chain"]}, cepp <= {targets["cepp"]}, track <= '
             f'{targets["track"]} (track on smooth cycles); (!) misses one; gross: frames '
             'more than 5 bounds + 0.5 m off. Offsets and moved anchors: no target.', '',
             'What each method published as valid: the ratio over those frames (the fraction '
             'published; frames valid while > 1 m off / of those, with a predicted RMSE under '
             'a third of the error):', '',
             *_field_published_table(report.rows), '',
             'Of the frames the information allows, the share published (frames refused as '
             'ambiguous whose true posture the ranges decide by the ambiguity odds, at the '
             "simulator's noise; a silent tag's frame allows none):", '',
             *_field_information_table(report.rows), '', *_field_heard_lines(report.rows), '',
             f'Track where its motion model holds (``cv``, {posterior["frames"]} frames): '
             f'{posterior["posterior_ratio"]:.2f} x the posterior CRLB, '
             f'{posterior["single_ratio"]:.2f} x the single-frame CRLB (the posterior bound '
             f'is {posterior["posterior_over_single"]:.2f} x the single-frame one).', '',
             *_field_authors_table(report.authors), '',
             f'Cost per frame (median, clean case, one run): chain {cost["chain_ms"]:.2f} '
             f'ms, track {cost["track_ms"]:.2f} ms ({cost["track_ms"] / cost["chain_ms"]:.2f} '
             f'x), cepp {cost["cepp_ms"]:.2f} ms. One warm fit: chain '
             f'{cost["fit_ms"]:.3f} ms, scipy least_squares (lm) {cost["scipy_ms"]:.3f} ms '
             f'({cost["fit_ms"] / cost["scipy_ms"]:.2f} x; answers within '
             f'{cost["largest_difference_rad"]:.1e} rad).']
    return '\n'.join(lines)


def family_markdown(report):
    """Format a :class:`~benchmarks.field_bench.FamilyReport`: what is published, per variant."""
    return '\n'.join([
        f"### The real links' family: the real_uwb preset varied, defaults, uncalibrated "
        f'({report.seeds} x {report.seconds:g} s per case at {field_bench.RATE:g} Hz, first '
        f'{field_bench.WARM_UP_S:g} s not scored)', '',
        'Per method: RMSE over the clean line-of-sight CRLB over the frames published as '
        'valid (the fraction published; frames valid while > 1 m off / of those, with a '
        'predicted RMSE under a third of the error: confidently wrong):', '',
        *_field_published_table(report.rows)])


def _soak_row(name, part):
    """Return the table row of a soak's part: ``'in-process'`` or ``'live node'``."""
    if name == 'in-process':
        rejected = sum(part['rejected'].values())
        decided = f'{part["decisions"]} ({part["postures"]} / {rejected})'
    else:
        decided = (f'{part["received"]} received ({part["published"]} / '
                   f'{part["unsolved"]}), {part["postures"]} postures here')
    return (f'| {name} | {part["frames"]} | {decided} | {part["frames_lost"]} | '
            f'{part["frames_per_s"]:.0f} | {_or_dash(part["rss_start_mb"])} | '
            f'{_or_dash(part["rss_warm_mb"])} | {_or_dash(part["rss_end_mb"])} | '
            f'{_or_dash(part["rss_peak_mb"])} | '
            f'{_or_dash(part["rss_growth_pct"], "+.1f", " %")} |')


def _soak_notes(report):
    """Return the lines on what went wrong: rejections, updates that raised, a live timeout."""
    in_process, live = report.in_process, report.live
    lines = []
    if in_process['rejected']:
        lines.append(f'In-process rejections by reason: {in_process["rejected"]}.')
    if in_process['errors']:
        lines += [f'{in_process["errors"]} updates raised; the first:', '```',
                  in_process['first_error'].rstrip(), '```']
    if live and not live['complete']:
        lines.append("The live part did not complete in time; the node's log ends:")
        lines += ['```', live['estimator_log_tail'].rstrip(), '```']
    return lines


def soak_markdown(report):
    """Format a :class:`~benchmarks.soak_bench.SoakReport` as a markdown table and notes."""
    parts = (('in-process', report.in_process), ('live node', report.live))
    met = (report.summary['frames_lost'] == 0 and report.summary['rss_ok']
           and report.summary.get('lag_accounted', True))
    lines = [f'### Soak: {report.method}, parser + assembler + estimator in-process, '
             'and epp_bag play --fast through the live node', '',
             '| part | frames | decisions (postures / rejected) | frames lost | frames/s | '
             'RSS start [MB] | after warm-up | end | peak | end vs warm-up |',
             '|---|---|---|---|---|---|---|---|---|---|',
             *[_soak_row(name, part) for name, part in parts if part is not None], '',
             'Frames lost: cycles sent that reached no decision (in-process), frames '
             'played that the node did not receive (live). Rejections are decisions.',
             *_soak_notes(report), *_lag_lines(report.lag),
             f'Target (nothing lost, RSS at the end within {soak_bench.RSS_TOLERANCE:.0%} of '
             f'warm-up): {"met" if met else "NOT met"}.']
    return '\n'.join(lines)


def _lag_lines(lag):
    """Return the lines of the lag phase (``soak_bench.soak_lag``), or none."""
    if lag is None:
        return []
    sums = (f'{lag["frames"]} played = {lag["received"]} received ({lag["published"]} '
            f'published, {lag["unsolved"]} unsolved, {lag["ignored"]} ignored) + '
            f'{lag["lost"]} lost + {lag["before_first"]} before the first')
    lines = [f'Lag: the live estimator stopped for {lag["lag_seconds"]:g} s of frames at '
             f'{lag["rate_hz"]:g} Hz: {sums}: '
             f'{"every frame accounted for" if lag["accounted"] else "NOT accounted for"}.']
    if not lag['accounted']:
        lines += ["The node's log ends:", '```', lag['estimator_log_tail'].rstrip(), '```']
    return lines


def _fuzz_escape_table(escapes):
    """Return the lines of the table of escapes: (protocol or field, escape) pairs."""
    return ['', '| protocol or field | exception, raised at | count | first input '
            '(its mutation) |', '|---|---|---|---|'] + [
        f'| {name} | {e["error"]}, {e["where"]} | {e["count"]} | '
        f'`{e["input"][:120]}` ({e["mutation"]}) |' for name, e in escapes]


def _fuzz_tracebacks(escapes):
    """Return the input and traceback of the first escape from each place."""
    lines, seen = [], set()
    for name, escape in escapes:
        if escape['where'] not in seen:
            seen.add(escape['where'])
            lines += ['', f'{name}: {escape["where"]}, input {escape["input"]}', '```',
                      escape['traceback'].rstrip(), '```']
    return lines


def fuzz_markdown(report, traceback_details=True):
    """
    Format a :class:`~benchmarks.fuzz_bench.FuzzReport`.

    Two tables (protocols, configuration fields), then the escapes and, with
    ``traceback_details``, their tracebacks.
    """
    lines = [f'### Fuzz: {report.inputs} generated inputs per protocol and per '
             f'configuration field (seed {report.seed})', '',
             '| protocol | inputs | gave records | frames closed | escaped | s |',
             '|---|---|---|---|---|---|']
    lines += [f'| {r["protocol"]} | {r["inputs"]} | {r["parsed"]} | {r["frames"]} | '
              f'{r["escaped"]} | {r["seconds"]:.1f} |' for r in report.protocols]
    lines += ['', '| configuration field | inputs | accepted | ConfigError | escaped | s | '
              'slowest input [s] |', '|---|---|---|---|---|---|---|']
    lines += [f'| {r["field"]} | {r["inputs"]} | {r["accepted"]} | {r["refused"]} | '
              f'{r["escaped"]} | {r["seconds"]:.1f} | {r["slowest_s"]:.3f} '
              f'({r["slowest_input"]}) |' for r in report.fields]
    lines += ['', f'Exceptions escaping: {report.escaped}.']
    escapes = [(row.get('protocol') or row['field'], escape)
               for row in report.protocols + report.fields for escape in row['escapes']]
    if escapes:
        lines += _fuzz_escape_table(escapes)
        lines += _fuzz_tracebacks(escapes) if traceback_details else []
    return '\n'.join(lines)


def driver_table(rows):
    """Format :func:`~benchmarks.driver_bench.run_driver_bench` rows as a plain table."""
    lines = ['transport   lines   seconds   lines/s   CPU ms / 1000 lines   reads']
    lines += [f"{r['transport']:<9} {r['lines']:>7} {r['seconds']:>9.2f} "
              f"{r['lines_per_s']:>9.0f} {r['cpu_ms_per_1000_lines']:>21.1f} {r['reads']:>7}"
              for r in rows]
    return '\n'.join(lines)


def driver_markdown(report):
    """Format a :class:`~benchmarks.driver_bench.DriverReport`: a heading, the plain table."""
    return '\n'.join(['### UWB driver: lines read per second over TCP and a pty', '',
                      '```', driver_table(report.rows), '```'])


#: The formatter of each report type.
def _speed_method_table(report):
    chain = report.rows.get('chain', {}).get('median')
    lines = ['| method | median [ms] | p90 | p99 | max | answer: median, p99 | p99 / median | '
             '/ chain | published | refused (lowest_joint 10 m) / good | garbage / good | '
             'target median, p99 |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for method, row in report.rows.items():
        target = speed_bench.TARGETS.get(method)
        lines.append(
            f'| {method} | {row["median"]:.2f} | {row["p90"]:.2f} | {row["p99"]:.2f} | '
            f'{row["max"]:.2f} | {row["answer_median"]:.2f}, {row["answer_p99"]:.2f} | '
            f'{_ratio(row["p99"], row["median"])} | '
            f'{_ratio(row["median"], chain)} | {row["published"]}/{report.frames} | '
            f'{_ratio(row["refused_median"], row["median"])} | '
            f'{_ratio(row["garbage_median"], row["median"])} | '
            + (f'{target[0]:g}, {target[1]:g} |' if target else '- |'))
    return lines


def _speed_growth_table(report):
    if not report.growth:
        return []
    methods = [key for key in report.growth[0] if key not in ('sections', 'anchors')]
    lines = ['', 'Median ms per frame as the pump grows (40 m boom):', '',
             '| sections | anchors | ' + ' | '.join(methods) + ' |',
             '|---|---|' + '---|' * len(methods)]
    lines += [f'| {row["sections"]} | {row["anchors"]} | '
              + ' | '.join(f'{row[m]:.1f}' for m in methods) + ' |' for row in report.growth]
    lines.append('')
    for axis, fitted in report.exponents.items():
        lines.append(f'- exponent in {axis}: '
                     + ', '.join(f'{m} {value:.2f}' for m, value in fitted.items()))
    return lines


def speed_markdown(report):
    """Return the speed suite's tables: CPU ms per frame, ratios, refused frames, growth."""
    chain = report.rows.get('chain', {}).get('median')
    lines = [f'### Speed: CPU time per frame, working cycle at sigma {speed_bench.SIGMA:g} m, '
             f'{report.frames} frames after {speed_bench.WARM_UP}, one BLAS thread', '',
             *_speed_method_table(report), '',
             'A frame: its update and what it teaches the learners (settle); the answer: '
             'the update alone, what a node publishes after.', '',
             f'scipy least_squares (LM), bare fit of the chain from a warm start: '
             f'{report.scipy_fit_ms:.2f} ms; chain update / scipy fit: '
             f'{_ratio(chain, report.scipy_fit_ms)} (target <= 0.5)',
             *_speed_growth_table(report)]
    return '\n'.join(lines)


def _compare_row(row):
    estimate = f'{row["estimate"]:.1e}' + (f' ({row["estimate_nan"]} frames NaN in one)'
                                           if row['estimate_nan'] else '')
    predicted = f'{row["predicted"]:.1e}' + (f' ({row["predicted_finite"]} finite)'
                                             if row['predicted_finite'] else '')
    scores = ' | '.join(f'{score["published"]}, {_or_dash(_finite(score["rmse"]), ".3f")}, '
                        f'{score["wrong"]} / {score["confidently"]}'
                        for score in row['scores'])
    return (f'| {row["stream"]} | {row["method"]} | {row["status"]} | {row["valid"]} | '
            f'{estimate} | {predicted} | {scores} |')


def _rounds(values):
    return ', '.join(f'{value:.2f}' for value in values)


def compare_markdown(report):
    """Return the comparison's tables: what differs per stream and method, and the speed."""
    lines = [f'### {report.head} against {report.base}: the same {report.frames} frames a '
             'stream', '',
             '| stream | method | status differs | valid differs | '
             'max estimate difference [m] | max predicted RMSE difference (relative) | '
             'base: published, RMSE [m], > 1 m / confidently | head: the same |',
             '|---|---|---|---|---|---|---|---|',
             *[_compare_row(row) for row in report.rows], '',
             'RMSE over the frames published as valid, against the truth; > 1 m: those frames '
             'more than 1 m off, and of them confidently: a predicted RMSE under a third of '
             'the error.', '',
             'CPU ms per frame on the working cycle after the warm-up, the median of each '
             'round (rounds alternate which tree runs first); the frame: update and settle, '
             'the answer: update:', '',
             '| method | base: frame | head: frame | head / base, median | base: answer | '
             'head: answer | head / base, median |', '|---|---|---|---|---|---|---|']
    for method, row in report.speed.items():
        frame = np.array(row['head']) / np.array(row['base'])
        answer = np.array(row['head_answer']) / np.array(row['base_answer'])
        lines.append(f'| {method} | {_rounds(row["base"])} | {_rounds(row["head"])} | '
                     f'{np.median(frame):.3f} ({frame.min():.2f}-{frame.max():.2f}) | '
                     f'{_rounds(row["base_answer"])} | {_rounds(row["head_answer"])} | '
                     f'{np.median(answer):.3f} ({answer.min():.2f}-{answer.max():.2f}) |')
    lines += ['', 'Every round of each tree gave the same statuses and estimates.'
              if report.repeatable else
              '**A tree gave different statuses or estimates from one round to the next.**']
    return '\n'.join(lines)


MARKDOWN = {
    Xie3dimReport: xie3dim_markdown,
    TrackingReport: tracking_markdown,
    LatencyReport: latency_markdown,
    ControllerReport: controller_markdown,
    BagsReport: bags_markdown,
    PaperReport: paper_markdown,
    integrity_bench.IntegrityReport: integrity_markdown,
    field_bench.FieldReport: field_markdown,
    field_bench.FamilyReport: family_markdown,
    soak_bench.SoakReport: soak_markdown,
    fuzz_bench.FuzzReport: fuzz_markdown,
    driver_bench.DriverReport: driver_markdown,
    CalibrationReport: lambda report: calibration_bench.markdown(report.fields),
    speed_bench.SpeedReport: speed_markdown,
    compare_bench.CompareReport: compare_markdown,
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
    Return the JSON line of ``python3 dev.py bench --json``: the commit and every report.

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
