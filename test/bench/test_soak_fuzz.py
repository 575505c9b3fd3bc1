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

"""The soak and fuzz benchmarks, short: the JSON contract, nothing lost, nothing escaping."""
import json
import subprocess
import sys

from benchmarks import bench, fuzz_bench, reports
from epp_ros.app.config import PUMP_PARAMETERS
from epp_ros.uwb.formats import FORMATS
import pytest

#: Inputs per protocol and per field here (the benchmark runs 100,000).
INPUTS = 2000


def test_short_soak_loses_nothing_and_ends_with_the_json_summary():
    result = subprocess.run([sys.executable, '-m', 'benchmarks.bench', 'soak', '--frames',
                             '2000', '--live-frames', '200', '--lag-seconds', '4', '--json'],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    for key in ('frames', 'frames_lost', 'rss_start_mb', 'rss_end_mb'):
        assert key in summary
    assert summary['frames'] == 2200
    assert summary['frames_lost'] == 0
    assert summary['in_process_frames_lost'] == 0 and summary['live_frames_lost'] == 0
    assert summary['rss_start_mb'] > 0 and summary['rss_end_mb'] > 0
    soak = summary['reports'][0]
    assert soak['in_process']['errors'] == 0
    assert soak['in_process']['decisions'] == 2000
    assert soak['live']['received'] == 200
    assert soak['live']['published'] + soak['live']['unsolved'] == 200
    assert '| in-process | 2000 |' in result.stdout
    # The estimator stopped 4 s while 50 frames a second came (its publisher keeps 100):
    # every frame played is received or counted lost, exactly.
    lag = soak['lag']
    assert lag['frames'] == 700 and lag['errors'] == 0
    assert lag['frames'] == lag['received'] + lag['lost'] + lag['before_first'], lag
    assert lag['accounted'] and summary['lag_accounted'] and summary['lag_frames'] == 700
    assert lag['received'] == lag['published'] + lag['unsolved'] + lag['ignored']
    assert 'every frame accounted for' in result.stdout


@pytest.mark.parametrize('protocol', [*FORMATS, 'auto'])
def test_no_exception_escapes_a_parser(protocol):
    row = fuzz_bench.fuzz_protocol(protocol, INPUTS, seed=1)
    assert row['inputs'] == INPUTS
    assert row['parsed'] > 0                    # the mutations reach the parsers' insides
    assert row['escaped'] == 0, row['escapes']


@pytest.mark.parametrize('field', list(PUMP_PARAMETERS))
def test_only_config_errors_come_out_of_the_validation(field):
    row = fuzz_bench.fuzz_field(field, INPUTS, seed=1)
    assert row['accepted'] + row['refused'] + row['escaped'] == INPUTS
    assert row['escaped'] == 0, row['escapes']


def test_fuzz_report_names_every_protocol_and_field():
    report = fuzz_bench.run(20, seed=2, protocols=['json'], fields=['frame_id'])
    text = reports.markdown(report)
    assert '| json | 20 |' in text and '| frame_id | 20 |' in text
    assert 'Exceptions escaping: 0.' in text


@pytest.mark.parametrize('argv', [['soak', '--frames', '0'], ['soak', '--frames', 'nan'],
                                  ['fuzz', '--inputs', '-1'], ['soak', '--live-frames', '1e9']])
def test_bad_counts_are_refused(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        bench.main(argv)
    assert exit_info.value.code == 2
    assert 'error: argument' in capsys.readouterr().err
