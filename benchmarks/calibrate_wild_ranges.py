#!/usr/bin/env python3
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
epp_calibrate on a recording with a fraction of its ranges wild (uniform 0-80 m).

    python3 benchmarks/calibrate_wild_ranges.py [--fraction F] [--seed N]

Synthesises the calibration tests' 60 s recording (offsets, moved outriggers, low noise),
replaces a fraction of its ranges (default 5 %) by uniform 0-80 m ones, and runs
``epp_calibrate`` on it and on the clean recording. Prints the ranges spoilt, those left
out and those left in (more than 5 cm off the clean recording's), each verdict, how far the
spoilt calibration's anchors and link offsets are from the clean one's, and its wall time.
"""
import argparse
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from epp_ros.app import bags
from epp_ros.app.config import default_config_path, load_pump_config
from epp_ros.cli import bag as bag_tool
from epp_ros.cli import calibrate
import numpy as np


def spoilt_copy(source, target, fraction, rng):
    """Copy a bag, a ``fraction`` of its ranges uniform 0-80 m; return how many."""
    messages, spoilt = [], 0
    for topic, msgtype, stamp, raw, qos in bags.read_all(source)[0]:
        if topic == bags.RANGES:
            message = bags.TYPESTORE.deserialize_cdr(raw, msgtype)
            values = np.array(message.position, dtype=float)
            wild = rng.random(values.size) < fraction
            wild[-1] = False                                # the frame number
            values[wild] = rng.uniform(0.0, 80.0, wild.sum())
            spoilt += int(wild.sum())
            message.position = values
            raw = bags.TYPESTORE.serialize_cdr(message, msgtype)
        messages.append((topic, msgtype, stamp, raw, qos))
    bags.write_raw(target, messages)
    return spoilt


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--fraction', type=float, default=0.05)
    parser.add_argument('--seed', type=int, default=5)
    args = parser.parse_args()
    config_path = default_config_path()
    config = load_pump_config(config_path)
    with tempfile.TemporaryDirectory() as folder:
        clean, wild = Path(folder) / 'clean', Path(folder) / 'wild'
        bag_tool.main(['synth', str(clean), '--field', 'offsets,anchors_moved,sigma_low',
                       '--duration', '60', '--start', '1000', '--seed', '0'])
        spoilt = spoilt_copy(clean, wild, args.fraction, np.random.default_rng(args.seed))
        window = (0.05, 200.0)
        read = calibrate.read_ranges(wild, config, window)
        error = read.ranges - calibrate.read_ranges(clean, config, window).ranges
        left_in = int((np.abs(error[np.isfinite(error)]) > 0.05).sum())
        started = time.monotonic()
        spoilt_run = _calibrated(wild, config_path)
        seconds = time.monotonic() - started
        clean_run = _calibrated(clean, config_path)
    print(f'spoilt {spoilt} ranges ({args.fraction:.0%}); left out {read.implausible} '
          f'implausible and {read.spikes} wild; left in {left_in} more than 5 cm off')
    for name, run in (('spoilt', spoilt_run), ('clean', clean_run)):
        print(f'{name}: {run["status"]}, exit status {run["exit"]}, range RMS '
              f'{run["rms_after_m"]:.3f} m')
    anchors = [np.linalg.norm(np.subtract(spoilt_run['anchors'][name]['after'],
                                          clean_run['anchors'][name]['after']))
               for name in config.anchor_names]
    offsets = np.subtract(spoilt_run['link_offsets'], clean_run['link_offsets'])
    print(f'spoilt against clean: anchors {max(anchors):.3f} m at most, link offsets '
          f'{np.sqrt(np.mean(offsets ** 2)):.3f} m RMS; the spoilt one took {seconds:.0f} s')


def _calibrated(bag, config_path):
    """Run epp_calibrate --json on a bag; its JSON result and exit status."""
    import json
    result = subprocess.run([sys.executable, '-m', 'epp_ros.cli.calibrate', str(bag),
                             '--config', str(config_path), '--json'],
                            capture_output=True, text=True)
    if not result.stdout.strip():
        raise SystemExit(result.stderr.strip())
    return dict(json.loads(result.stdout.strip().splitlines()[-1]), exit=result.returncode)


if __name__ == '__main__':
    main()
