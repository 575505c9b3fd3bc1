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
One BLAS thread per process for the nodes and tools.

The estimator's matrices have tens of rows. OpenBLAS starts a thread per core for a
product or a factorisation past a small size and then spins them between calls: on a pump
with 16 anchors that made a CEPP frame ten times slower (0.5 s instead of 50 ms) and took the
second core from the driver. One thread is never slower at these sizes.
"""
import numpy  # noqa: F401 (loads numpy's BLAS, so that it is limited)
from scipy.linalg import lapack  # noqa: F401 (loads scipy's, the LAPACK the solvers call)
from threadpoolctl import threadpool_info, threadpool_limits

__all__ = ['single_blas_thread', 'blas_threads']


def single_blas_thread():
    """Limit every BLAS library loaded in this process (numpy's, scipy's) to one thread."""
    threadpool_limits(limits=1, user_api='blas')


def blas_threads():
    """Return the largest thread count of the BLAS libraries loaded in this process."""
    return max((pool['num_threads'] for pool in threadpool_info()
                if pool['user_api'] == 'blas'), default=1)
