"""The console tools run end to end and keep their output contracts."""
import argparse
import json
import subprocess
import sys

import pytest

from epp_ros.tools import bench, demo


def test_demo_runs_the_pipeline_and_ends_with_a_json_summary(tmp_path):
    plot = tmp_path / 'boom.png'
    result = subprocess.run([sys.executable, '-m', 'epp_ros.tools.demo', '--duration', '6',
                             '--sigma', '0.1', '--garbage', '0', '--json', '--plot', str(plot)],
                            capture_output=True, text=True, timeout=90)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(summary) == {'frames', 'rmse_m', 'max_joint_error_m', 'latency_p50_ms',
                            'latency_p99_ms', 'dropped_frames', 'method'}
    assert summary['frames'] >= 30 and summary['method'] == 'cepp'
    assert 0.0 < summary['rmse_m'] < 0.8                 # CEPP here: ~3.3 sigma
    assert summary['dropped_frames'] == 0
    assert 0.0 < summary['latency_p50_ms'] <= summary['latency_p99_ms']
    assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_demo_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        demo.parse_args(['--rate', '0'])
    with pytest.raises(SystemExit):
        demo.parse_args(['--method', 'magic'])
    assert demo.main(['--config', '/nonexistent.yaml', '--duration', '1']) == 2


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


def test_bench_refuses_tpsm_where_no_angles_are_simulated():
    with pytest.raises(SystemExit):
        bench.main(['xie3dim', '--methods', 'tpsm'])
