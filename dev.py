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
Set up the project's own venv if needed, then run the demo or the test suite.

    python3 dev.py demo [epp_demo options]    # live demo on the built-in simulated pump
    python3 dev.py test [pytest options]      # the whole test suite
    python3 dev.py bench SUITE [options]      # the benchmarks (benchmarks/, not installed)

The venv (.venv/) is rebuilt from requirements.txt only when that file, setup.py,
setup.cfg or this script changed since the last run, so a second run starts at once.
Needs nothing but Python >= 3.10.
"""
import hashlib
import os
from pathlib import Path
import subprocess
import sys
import venv

ROOT = Path(__file__).resolve().parent
VENV = ROOT / '.venv'
PYTHON = VENV / 'bin' / 'python'
STAMP = VENV / '.epp-ros-stamp'
INPUTS = ('requirements.txt', 'setup.py', 'setup.cfg', 'dev.py')


def _fingerprint():
    digest = hashlib.sha256()
    for name in INPUTS:
        digest.update((ROOT / name).read_bytes())
    digest.update(sys.version.encode())
    return digest.hexdigest()


def ensure_venv():
    """Create or update .venv so that it matches requirements.txt; return its python."""
    fingerprint = _fingerprint()
    if PYTHON.exists() and STAMP.exists() and STAMP.read_text() == fingerprint:
        return PYTHON
    print('dev.py: preparing .venv (first run or changed requirements) ...', flush=True)
    if not PYTHON.exists():
        venv.EnvBuilder(with_pip=True).create(VENV)
    pip = [str(PYTHON), '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check']
    subprocess.run(pip + ['-r', str(ROOT / 'requirements.txt')], check=True)
    # Compat mode puts the checkout on sys.path: modules added later import without a reinstall.
    subprocess.run(pip + ['--no-deps', '--no-build-isolation', '--config-settings',
                          'editable_mode=compat', '-e', str(ROOT)], check=True)
    STAMP.write_text(fingerprint)
    return PYTHON


def main(argv):
    if not argv or argv[0] not in ('demo', 'test', 'bench'):
        print(__doc__.strip())
        return 2
    python = ensure_venv()
    command, rest = argv[0], argv[1:]
    env = dict(os.environ, AMENT_PREFIX_PATH=str(VENV), VIRTUAL_ENV=str(VENV))
    # Quick Fast DDS discovery for processes started together (unless the user set one).
    env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                   str(ROOT / 'config' / 'fastdds_fast_discovery.xml'))
    if command != 'test':   # (the tests' conftest.py does it for them)
        # The kernels are compiled once per checkout (numba caches them beside their
        # source): here rather than in the first frame of the demo or a benchmark.
        subprocess.run([str(python), '-c', 'from epp_ros.core import compile_fit; '
                        'compile_fit()'], cwd=ROOT, env=env, check=True)
    if command == 'test':
        args = [str(python), '-m', 'pytest'] + rest
    elif command == 'bench':
        args = [str(python), '-m', 'benchmarks'] + rest
    else:
        args = [str(VENV / 'bin' / 'epp_demo')] + rest
    child = subprocess.Popen(args, cwd=ROOT, env=env)
    while True:
        try:
            return child.wait()
        except KeyboardInterrupt:   # Ctrl-C reaches the child too; let it finish cleanly
            continue


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
