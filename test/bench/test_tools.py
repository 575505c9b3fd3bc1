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

"""The console tools run end to end and keep their output contracts."""
import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import subprocess
import sys

from benchmarks import bench, compare_bench, experiments, field_bench, reports
from epp_ros.cli import demo
from epp_ros.core.simulation import (FIELD_EFFECTS, field_effects, FieldEffects, RangeNoise,
                                     simulate_field, truck_pump, working_cycle, WorkingMotion)
import numpy as np
import pytest


def test_demo_runs_the_pipeline_and_ends_with_a_json_summary(tmp_path):
    plot = tmp_path / 'boom.png'
    # Until 30 postures arrived, however long a loaded machine takes (at most 80 s).
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.demo', '--postures', '30',
                             '--duration', '80', '--sigma', '0.1', '--garbage', '0', '--json',
                             '--plot', str(plot)], capture_output=True, text=True, timeout=150)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(summary) == {'frames', 'rmse_m', 'max_joint_error_m', 'latency_p50_ms',
                            'latency_p99_ms', 'dropped_frames', 'method'}
    assert summary['frames'] >= 30 and summary['method'] == 'cepp'
    assert 0.0 < summary['rmse_m'] < 0.8                 # CEPP here: ~3.3 sigma
    # A frame the checks refuse gets no posture either (a cold start's first frames can be
    # ambiguous); that none is lost on the way is test_pipeline_system's.
    assert summary['dropped_frames'] <= 3
    assert 0.0 < summary['latency_p50_ms'] <= summary['latency_p99_ms']
    assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def demo_process(*args, timeout=120, **options):
    """Run epp_demo as a program; the CompletedProcess."""
    return subprocess.run([sys.executable, '-m', 'epp_ros.cli.demo', *args],
                          capture_output=True, text=True, timeout=timeout, **options)


@pytest.mark.parametrize('bad', [
    ['--rate', 'nan'], ['--rate', 'inf'], ['--rate', '1e6'], ['--rate', '0'],
    ['--sigma', '-1'], ['--sigma', 'nan'], ['--drop', '2'], ['--seed', '-1'],
    ['--duration', 'nan'], ['--duration', 'inf'], ['--postures', '0'], ['--method', 'magic'],
    ['--plot', '/proc/x.png'], ['--plot', 'boom.xyz'], ['--record', '/proc/nope/bag']])
def test_demo_refuses_what_it_cannot_run_in_one_line_before_starting(bad):
    """Every option as the emulator checks it; outputs checked before anything runs."""
    result = demo_process(*bad, '--duration' if '--duration' not in bad else '--seed', '5')
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith('epp_demo: error: ') and result.stdout == ''


def test_demo_fails_when_its_config_cannot_be_read():
    assert demo.main(['--config', '/nonexistent.yaml', '--duration', '1']) == 2


def test_demo_output_that_goes_away_ends_it_quietly(tmp_path):
    """`| head -1`, /dev/full and a closed stdout: no traceback, and the pipeline stops."""
    command = [sys.executable, '-m', 'epp_ros.cli.demo', '--plain', '--duration', '60']
    piped = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = piped.stdout.readline()                 # then the reader goes away
    piped.stdout.close()
    assert piped.wait(120) == 0 and first
    assert b'Traceback' not in piped.stderr.read()
    piped.stderr.close()
    with open('/dev/full', 'w') as full:
        result = subprocess.run(command, stdout=full, stderr=subprocess.PIPE, text=True,
                                timeout=120)
    assert result.returncode == 2 and 'Traceback' not in result.stderr
    assert 'cannot write the output' in result.stderr
    closed = subprocess.run(['sh', '-c', '"$0" "$@" >&-', *command], capture_output=True,
                            text=True, timeout=120)
    assert closed.returncode == 2 and closed.stderr.count('\n') == 1
    assert 'stdout is closed' in closed.stderr


def test_bench_prints_tables_and_json(capsys):
    assert bench.main(['xie3dim', '--trials', '3', '--methods', 'epp2', 'cepp',
                       '--option', 'tol=1e-7', '--json']) == 0
    out = capsys.readouterr().out
    assert '| epp2 |' in out and '| cepp |' in out and 'RMSE / CRLB' in out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert report['trials'] == 3 and [r['method'] for r in report['rows']] == ['epp2', 'cepp']
    assert all(r['rmse_m'] < 5.0 for r in report['rows'])


def test_bench_option_parsing():
    assert bench.parse_option('anchor_weight=inf')[1] == float('inf')
    assert bench.parse_option('slew_iterations=3') == ('slew_iterations', 3)
    assert bench.parse_option('tol=1e-9') == ('tol', 1e-9)
    assert bench.parse_option('predict_slew=false') == ('predict_slew', False)
    assert bench.parse_option('predict_slew=True') == ('predict_slew', True)
    with pytest.raises(argparse.ArgumentTypeError):
        bench.parse_option('novalue')


def test_bench_paper_writes_tables_json_and_plots(tmp_path, capsys):
    out = tmp_path / 'paper'
    assert bench.main(['paper', '--runs', '2', '--seconds', '3', '--out', str(out)]) == 0
    text = (out / 'paper.md').read_text()
    assert text == capsys.readouterr().out.split('written to')[0].rstrip('\n') + '\n'
    # The paper's published figures stand next to ours, and the commit is named.
    for published in ('(0.286)', '(1.639)', '(2.533)', '(4.765)', '0.947 (EMBED/CEPP)'):
        assert published in text
    assert 'commit ' in text and 'chain+angles' in text
    report = json.loads((out / 'paper.json').read_text())
    assert set(report['reports']) == {'sweep_eta', 'sweep_sigma', 'nlos', 'xie3dim',
                                      'tracking', 'targets'}
    sweep = report['reports']['sweep_sigma']
    assert [row['sigma'] for row in sweep['rows']] == [0.1, 0.2, 0.5, 1.0, 2.0]
    assert set(sweep['rows'][0]['methods']) == {'sdp', 'srls', 'epp1', 'epp2', 'cepp', 'chain'}
    assert set(report['reports']['nlos']['methods']) == {'sdp', 'srls', 'tpsm', 'epp2', 'cepp',
                                                         'chain'}
    targets = report['reports']['targets']['rows']
    assert len(targets) == 18
    assert all(row['search_misses'] >= 0 and row['local_fit_rmse_m'] > 0 for row in targets)
    assert all(0 <= row['other_posture_frames'] <= row['runs']
               and row['rmse_same_posture_m'] > 0 for row in targets)
    for name in ('rmse_vs_eta.png', 'rmse_vs_sigma.png'):
        assert (out / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_the_authors_cepp_solves_in_the_true_plane_from_cold_starts():
    from epp_ros.core.model.plane import fit_slew
    from epp_ros.core.simulation.simulate import xie3dim
    model, truth = xie3dim()
    authors = experiments.TruthPlaneCEPP(model, truth, sigma=1.0)
    frames = experiments.xie3dim_frames(model, truth, 5, seed=1)
    rmses, lengths, _, valid, _ = experiments.run_frames(authors, frames, [truth] * 5,
                                                         cold=True)
    assert np.isnan(valid).all()            # the paper's variant publishes every frame
    assert experiments.summarize(rmses, lengths, np.ones(5), valid, valid).published_fraction \
        is None
    assert len(authors.slews) == 5 and authors.slew_error() < 1e-9
    np.testing.assert_allclose(authors.slews, fit_slew(truth, model.base), atol=1e-9)
    assert np.all(rmses < 5.0) and np.all(lengths < 1e-4)     # CEPP holds the lengths


def test_xie3dim_gives_the_mean_and_rms_next_to_the_published_means_of_3000_trials():
    variants = [v for v in experiments.PAPER_XIE3DIM if v.truth_plane or v.method == 'srls']
    report = experiments.xie3dim_experiment(variants, 4, seed=0)
    assert [row.method for row in report.rows] == [v.label for v in variants]
    for row in report.rows:
        assert 0.0 < row.mean_rmse_m <= row.rmse_m
        assert row.published.trials == 3000
    assert [row.published.mean_rmse_m for row in report.rows] == [0.947, 0.947, 2.27]
    assert report.truth_plane_slew_error_rad < 1e-9
    text = reports.markdown(report)
    assert 'mean RMSE of 3,000 trials' in text and '0.947 (EMBED/CEPP); RMS 0.997' in text
    assert 'one trial' not in text
    with pytest.raises(TypeError):
        reports.markdown({'suite': 'xie3dim'})


def test_the_method_tables_score_what_a_user_gets_beside_every_frame():
    summary = experiments.summarize(np.array([0.1, 2.0, 0.5, 1.5]), np.zeros((4, 5)),
                                    np.ones(4), np.array([1.0, 1.0, 0.0, 1.0]),
                                    np.array([0.1, 0.5, np.nan, 0.6]))
    assert summary.valid_rmse_m == pytest.approx(np.sqrt((0.01 + 4.0 + 2.25) / 3))
    assert summary.rmse_m == pytest.approx(np.sqrt((0.01 + 4.0 + 0.25 + 2.25) / 4))
    # 2.0 m off, 0.5 predicted: under a third, confidently wrong; 1.5 off, 0.6 predicted: not.
    assert (summary.published_fraction, summary.wrong_valid, summary.confidently_wrong) == \
        (0.75, 2, 1)
    report = experiments.xie3dim_suite(['chain'], 6, 0, {})
    row = report.rows[0]
    assert 0.0 <= row.published_fraction <= 1.0 and row.wrong_valid >= 0
    assert f'{row.published_fraction:.0%} |' in reports.markdown(report)
    # The sweep: the same frames at rising odds; a frame refused at lower odds stays refused.
    sweep = report.ambiguity
    assert [(r.method, r.odds) for r in sweep] == [('chain', odds)
                                                   for odds in experiments.AMBIGUITY_ODDS]
    published = [r.published_fraction for r in sweep]
    assert published == sorted(published, reverse=True)
    assert '| chain | 1000 |' in reports.markdown(report)


def test_bench_refuses_tpsm_where_no_angles_are_simulated():
    with pytest.raises(SystemExit):
        bench.main(['xie3dim', '--methods', 'tpsm'])


def test_bench_integrity_reports_every_case_and_method(capsys):
    from benchmarks import integrity_bench
    assert bench.main(['integrity', '--methods', 'chain', 'cepp', '--seconds', '6',
                       '--json']) == 0
    out = capsys.readouterr().out
    assert '### Integrity' in out and '| chain |' in out and '| cepp |' in out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert report['suite'] == 'integrity' and report['seconds'] == 6.0
    assert list(report['cases']) == list(integrity_bench.CASES)
    assert [row['method'] for row in report['rows']] == ['chain', 'cepp']
    for row in report['rows']:
        assert isinstance(row['wrong_valid'], int) and 0 <= row['wrong_valid'] <= row['frames']
        assert 0 <= row['unrecovered'] <= row['events'] and row['events'] >= 5
        assert 0 <= row['clean_rejected'] <= row['clean_scored'] == 60
        assert 0 <= row['broken_rejected'] <= row['broken_scored'] < 5 * 60
        assert 0.0 <= row['false_rejection_clean'] <= 1.0
        assert 0.0 <= row['false_rejection_broken'] <= 1.0
        if row['recovery_worst_s'] is not None:
            assert 0.0 < row['recovery_median_s'] <= row['recovery_worst_s'] <= 6.0
        assert 0.0 < row['ms_median'] <= row['ms_p99']
    cases = [row for row in report['case_rows'] if row['method'] == 'chain']
    assert [row['case'] for row in cases] == list(integrity_bench.CASES)
    for row in cases:
        assert 0 <= row['wrong_valid'] <= row['valid'] <= row['frames']
        assert len(row['wrong_indices']) == row['wrong_valid']
        assert sum(row['statuses'].values()) == row['frames']
        assert len(row['recoveries_s']) == row['events']
        assert row['events'] == 0 or row['case'] in integrity_bench.BROKEN_CASES
    frames = {row['case']: row['frames'] for row in cases}
    assert frames['clean'] == 60 and frames['two_anchors'] == frames['one_short'] == 12


def test_integrity_streams_break_what_they_say():
    from benchmarks import integrity_bench as ib
    streams = {s.case: s for s in ib.build_streams(20.0, 3)}
    assert streams['clean'].scored.all() and not streams['clean'].events
    for case in ib.BROKEN_CASES:
        stream = streams[case]
        assert stream.events and len(stream.labels) == len(stream.events)
        broken = np.zeros(len(stream.stamps), bool)
        for first, last in stream.events:
            broken[first:last + 1] = True
            assert first >= ib.LEAD_S * ib.RATE
        assert np.array_equal(stream.scored, ~broken)
    tip = streams['corrupt_tip']
    first = tip.events[0][0]
    intact = ib.cycle_stream(ib.truck_pump(), 20.0, 3, 'corrupt_tip').ranges[first]
    same = np.isclose(tip.ranges[first], intact) | np.isnan(intact)
    assert same[:-1].all() and not same[-1].all()
    bursts = [last - first + 1 for first, last in streams['garbage_bursts'].events]
    assert all(ib.BURST_FRAMES[0] <= n <= ib.BURST_FRAMES[1] for n in bursts)
    assert streams['absurd'].labels[:2] == ['all 0 m', 'all 0.1 m']
    two = streams['two_anchors']
    assert two.cold and (np.isfinite(two.ranges).any(axis=1).sum(axis=1) <= 2).all()
    short = streams['one_short']
    assert short.cold and not short.scored.any()
    # Each frame's noise (within 5 sigma), and one range SHORT short.
    excess = short.ranges - short.model.ranges(short.truths)
    ordered = np.sort(np.nan_to_num(excess, nan=0.0).reshape(len(excess), -1), axis=1)
    assert (ordered[:, 0] <= -ib.SHORT[0] + 5 * ib.SIGMA).all()
    assert (ordered[:, 0] >= -ib.SHORT[1] - 5 * ib.SIGMA).all()
    assert (ordered[:, 1] >= -5 * ib.SIGMA).all()
    for shape in ('collinear', 'coincident'):
        anchors = streams[shape].model.anchors
        centred = anchors - anchors.mean(axis=0)
        extent = np.linalg.svd(centred, compute_uv=False)
        assert extent[1] < 0.1 and (extent[0] < 0.1) == (shape == 'coincident')


def test_bench_driver_suite_prints_its_table(capsys):
    assert bench.main(['driver', '--json']) == 0
    out = capsys.readouterr().out
    assert '### UWB driver' in out and 'lines/s' in out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert report['suite'] == 'driver'
    assert [row['transport'] for row in report['rows']] == ['tcp', 'pty']
    assert all(row['complete'] and row['lines'] == 20000 for row in report['rows'])


def test_bench_help_lists_the_new_suites(capsys):
    with pytest.raises(SystemExit):
        bench.main(['--help'])
    out = capsys.readouterr().out
    assert 'integrity' in out and 'driver' in out
    with pytest.raises(SystemExit):
        bench.main(['integrity', '--methods', 'tpsm'])


@pytest.mark.parametrize('argv', [
    ['epp_bag', 'synth', 'OUT', '--duration', 'nan'],
    ['epp_bag', 'synth', 'OUT', '--rate', 'inf'],
    ['epp_bag', 'synth', 'OUT', '--duration', '1e12'],
    ['epp_bag', 'synth', 'OUT', '--drop', '2'],
    ['epp_bag', 'synth', 'OUT', '--sigma', 'nan'],
    ['epp_bag', 'synth', 'OUT', '--seed', '-1'],
    ['epp_bag', 'play', 'BAG', '--rate', '0'],
    ['epp_bag', 'play', 'BAG', '--clock', '-5'],
    ['uwb_emulator', '--tcp', '127.0.0.1:99999'],
    ['uwb_emulator', '--pty', '--rate', 'nan'],
    ['uwb_emulator', '--pty', '--drop', '1.5'],
])
def test_bad_numbers_on_the_command_line_give_one_line_and_status_2(argv, tmp_path):
    args = [str(Path(sys.executable).parent / argv[0])] + [
        str(tmp_path / a) if a in ('OUT', 'BAG') else a for a in argv[1:]]
    result = subprocess.run(args, capture_output=True, text=True, timeout=60)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert 'error' in lines[0] and 'Traceback' not in result.stderr
    assert not (tmp_path / 'OUT').exists()


def test_bench_field_prints_every_case_against_the_bounds(capsys):
    """A short run: every case, method and part is printed, with finite ratios."""
    assert bench.main(['field', '--seconds', '7', '--seeds', '1', '--trials', '2',
                       '--json']) == 0
    out = capsys.readouterr().out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert [row['case'] for row in report['rows']] == list(field_bench.CASES)
    for row in report['rows']:
        assert all(np.isfinite(row[method]['ratio']) for method in field_bench.METHODS)
    assert 0.0 < report['posterior']['posterior_ratio'] < 10.0
    assert '| all |' in out and 'posterior CRLB' in out and 'scipy least_squares' in out
    for row in report['rows']:
        for method in field_bench.METHODS:
            assert 0.0 <= row[method]['allowed_share'] <= 1.0 and row[method]['decidable'] >= 0
    assert 'the information allows' in out


def test_the_real_links_family_is_each_a_real_uwb_variant_and_printed(capsys):
    """Each variant changes the real_uwb preset; a short run of two prints their rows."""
    real = FIELD_EFFECTS['real_uwb']
    for name, (spec, motion, *pump) in field_bench.FAMILY.items():
        effects = spec if isinstance(spec, FieldEffects) else field_effects(spec)
        assert effects.link_offset > 0 and effects.bias_curve, name
        assert effects != real or motion != 'working' or pump, name
    frames, model, _ = field_bench.case_frames('+ tdma, four anchors, joystick', 1.0, 0)
    assert model.n_anchors == 4 and frames[0].inputs()['ranges'].shape == (5, 4)
    names = ('outliers x10, 3 m', '+ dropouts')
    report = field_bench.run_family(6.0, 1, names)
    assert [row['case'] for row in report.rows] == list(names)
    for row in report.rows:
        for method in field_bench.METHODS:
            cell = row[method]
            assert 0.0 <= cell['valid'] <= 1.0 and cell['confidently_wrong'] >= 0
            assert np.isfinite(cell['ratio'])
    printed = reports.markdown(report)
    assert "real links' family" in printed and '| outliers x10, 3 m |' in printed
    unpublished = dict(report.rows[0]['chain'], valid=0.0, published_ratio=float('nan'))
    nothing = dict(report.rows[0], chain=unpublished)
    assert '| outliers x10, 3 m | - (0 %; ' in reports.markdown(replace(report, rows=[nothing]))
    assert 'family' in bench.parse_args(['family']).suites


def test_the_information_oracle_decides_a_fold_only_where_the_ranges_do():
    """A fold metres away at sigma 0.1 m is decided; at 50 m it is not, nor a silent tag."""
    model = truck_pump()
    effects = FieldEffects()
    frame = simulate_field(model, WorkingMotion(model, np.random.default_rng(0)), 1.0,
                           effects, np.random.default_rng(1), 0.1)[-1]
    assert field_bench.truth_decides(model, frame, effects, [2, 5])
    assert not field_bench.truth_decides(model, frame, replace(effects, sigma=50.0), [2, 5])
    assert field_bench.truth_decides(model, frame, replace(effects, sigma=50.0), [])
    frame.ranges[2] = np.nan
    assert not field_bench.truth_decides(model, frame, effects, [])


def test_bench_speed_prints_times_ratios_and_growth(capsys):
    """A short run: every method's percentiles in order, finite ratios, both exponents."""
    assert bench.main(['speed', '--methods', 'chain', 'cepp', '--seconds', '1', '--json']) == 0
    out = capsys.readouterr().out
    assert '### Speed' in out and 'exponent in anchors' in out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert report['suite'] == 'speed' and list(report['rows']) == ['chain', 'cepp']
    for row in report['rows'].values():
        assert 0.0 < row['median'] <= row['p90'] <= row['p99'] <= row['max']
        assert 0 <= row['published'] <= report['frames'] == 10
        assert np.isfinite([row['refused_median'], row['garbage_median']]).all()
        # The answer is the frame's update without what it teaches: never more.
        assert 0.0 < row['answer_median'] <= row['median']
        assert row['answer_p99'] <= row['p99']
    assert set(report['exponents']) == {'sections', 'anchors'}
    assert all(np.isfinite(list(fitted.values())).all()
               for fitted in report['exponents'].values())


def test_bench_compare_runs_both_trees_on_the_same_frames(tmp_path, capsys, monkeypatch):
    """
    This checkout against its own HEAD, unpacked and run in fresh processes: what CI has.

    Where the checkout has uncommitted changes the figures may differ; the table and the
    report's shape hold either way, and a clean checkout's trees agree to the last bit.
    The workers run the numpy paths: the unpacked tree's kernels would compile for a
    minute.
    """
    monkeypatch.setattr(compare_bench, 'STREAMS', ('working', 'garbage'))
    monkeypatch.setenv('EPP_ROS_COMPILED', '0')
    report = compare_bench.run('HEAD', ('chain',), seconds=4.0, rounds=2, cache=tmp_path)
    assert (tmp_path / compare_bench.unpacked('HEAD', tmp_path)[0] / 'epp_ros').is_dir()
    assert report.frames == 40 and report.repeatable
    assert [(row['stream'], row['method']) for row in report.rows] == [
        ('working', 'chain'), ('garbage', 'chain')]
    assert len(report.speed['chain']['base']) == len(report.speed['chain']['head']) == 2
    assert all(value > 0.0 for values in report.speed['chain'].values() for value in values)
    working, garbage = (dict(zip(('base', 'head'), row['scores'])) for row in report.rows)
    for score in working.values():          # the clean cycle: every frame, near the truth
        assert score['published'] == 40 and score['rmse'] < 0.5 and score['wrong'] == 0
    for score in garbage.values():          # garbage: nothing published
        assert score['published'] == score['wrong'] == 0 and np.isnan(score['rmse'])
    if not report.head.endswith('changes'):
        for row in report.rows:
            assert row['status'] == row['valid'] == row['estimate_nan'] == 0
            assert row['estimate'] == row['predicted'] == 0.0
            assert row['scores'][0] == row['scores'][1]
    print(reports.markdown(report))
    assert 'head / base' in capsys.readouterr().out


def test_bench_compare_refuses_a_commit_that_is_not_there_in_one_line(capsys):
    with pytest.raises(SystemExit) as stopped:
        bench.main(['compare', '--base', 'no-such-commit'])
    assert str(stopped.value).startswith("python3 dev.py bench compare: --base 'no-such-commit'")
    assert '\n' not in str(stopped.value)


def test_compare_counts_what_differs_between_two_trees():
    """Statuses, validity, estimates (NaN where one has none) and predicted RMSEs."""
    def results(status, valid, estimate, predicted):
        return {'working': {'chain': {'status': np.array(status), 'valid': np.array(valid),
                                      'estimate': np.array(estimate, dtype=float),
                                      'predicted': np.array(predicted, dtype=float)}}}
    old = results(['ok', 'ok', 'ambiguous'], [True, True, False],
                  [[[0.0, 0.0, 1.0]], [[1.0, 0.0, 1.0]], [[2.0, 0.0, 1.0]]], [0.1, 0.2, np.inf])
    new = results(['ok', 'inconsistent', 'ambiguous'], [True, False, False],
                  [[[0.0, 0.0, 1.0]], [[1.0, 0.5, 1.0]], [[np.nan, 0.0, 1.0]]], [0.1, 0.3, 0.4])
    truth = {'working': np.array([[[0.0, 0.0, 1.0]], [[1.0, 2.0, 1.0]], [[2.0, 0.0, 1.0]]])}
    row, = compare_bench.differences(old, new, truth)
    assert (row['status'], row['valid']) == (1, 1)
    assert row['estimate'] == 0.5 and row['estimate_nan'] == 1
    assert row['predicted'] == pytest.approx(0.5) and row['predicted_finite'] == 1
    # Published: the first two (base: the second 2 m off at 0.2 predicted) / the first.
    assert row['scores'][0] == {'published': 2, 'rmse': pytest.approx(np.sqrt(2.0)),
                                'wrong': 1, 'confidently': 1}
    assert row['scores'][1] == {'published': 1, 'rmse': 0.0, 'wrong': 0, 'confidently': 0}


def test_bench_controller_runs_the_node_on_one_shared_core(capsys, monkeypatch):
    """A short run: the estimator on one core beside a busy process, every frame counted."""
    from benchmarks import node_bench
    pinned = []
    real_affinity = os.sched_setaffinity
    monkeypatch.setattr(node_bench.os, 'sched_setaffinity',
                        lambda pid, cores: (pinned.append((pid, set(cores))),
                                            real_affinity(pid, cores)))
    if len(os.sched_getaffinity(0)) < 2:                # no core to feed it from
        with pytest.raises(RuntimeError, match='two cores'):
            bench.main(['controller', '--methods', 'chain', '--controller-seconds', '3'])
        return
    assert bench.main(['controller', '--methods', 'chain', '--controller-seconds', '3',
                       '--json']) == 0
    out = capsys.readouterr().out
    assert '### posture_estimator on one core' in out
    report = json.loads(out.strip().splitlines()[-1])['reports'][0]
    assert report['suite'] == 'controller' and len(report['rows']) == 1
    row = report['rows'][0]
    assert row['method'] == 'chain' and row['frames'] == 30
    assert 0.0 < row['p50_ms'] <= row['p90_ms'] <= row['p99_ms'] <= row['max_ms']
    assert row['unanswered'] <= 3           # a cold start's first frames can be refused
    # The node saw every frame (and the 10 warm-up ones); what it refused published nothing.
    assert row['received'] == row['frames'] + 10
    assert 0 <= row['refused'] and row['unanswered'] <= row['refused']
    # The busy process and the estimator on core 0; this process elsewhere, then restored.
    cores = [cores for pid, cores in pinned]
    assert cores[0] == cores[2] == {0} and 0 not in cores[1]
    assert os.sched_getaffinity(0) == cores[3]


def test_live_parameter_changes_are_answered_while_frames_flow():
    """set_parameters twice a second over DDS to a running estimator: every call accepted."""
    from benchmarks.node_bench import parameter_response
    model = truck_pump()
    rng = np.random.default_rng(0)
    motion = working_cycle(model, 10.0, 10.0, rng=np.random.default_rng(1))
    frames = [RangeNoise(sigma=0.1).apply(model.ranges(joints), rng)[0]
              for joints in motion.joints]
    responses, latencies, _, unanswered = parameter_response('chain', frames, 3.0)
    assert unanswered == 0 and len(responses) == 6      # frames 0, 5, ..., 25 of 30
    assert len(latencies) > 0                           # and postures came back meanwhile
