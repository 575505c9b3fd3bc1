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


"""One BLAS thread in the nodes and tools, numpy's and scipy's alike."""
import os
import subprocess
import sys

CHECK = """
from epp_ros.app.threads import blas_threads, single_blas_thread
from threadpoolctl import threadpool_info
before = blas_threads()
single_blas_thread()
libraries = [pool for pool in threadpool_info() if pool['user_api'] == 'blas']
print(before, blas_threads(), len(libraries))
"""


def test_every_blas_library_runs_one_thread():
    """A fresh process, told to use two threads, ends with one in each library it loaded."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS='2', OMP_NUM_THREADS='2')
    run = subprocess.run([sys.executable, '-c', CHECK], env=env, capture_output=True,
                         text=True, timeout=120, check=True)
    before, after, libraries = map(int, run.stdout.split())
    assert before == 2                  # the test would pass vacuously with one already
    assert after == 1
    assert libraries >= 1               # the wheels': numpy's OpenBLAS and scipy's
