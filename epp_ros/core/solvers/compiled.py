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
The switch for the compiled kernels, and how they are compiled.

Five hot paths have a numba-compiled twin of their numpy code: the chain's and the
tracker's fit (``estimation.methods.compiled_chain``), Newton's method in the points
that finishes CEPP (``solvers.compiled_points``), the plane CEPP solves in
(``model.compiled_plane``), the NLOS loss of candidate positions, which the fold
searches and the integrity checks score (``model.compiled_nlos``), and the bounds the
integrity checks judge a frame by (``model.compiled_bounds``); the boom's geometry they
share is ``model.compiled_boom``. The numpy code stays
the reference and the path taken where numba is not installed or ``EPP_ROS_COMPILED=0``
is in the environment. A kernel module (and numba, about 0.4 s) is imported at its
first use only.
"""
from functools import lru_cache
import importlib
import importlib.util
import os

import numpy as np

__all__ = ['COMPILED', 'compiled', 'kernel', 'plain']

#: Whether the kernels run compiled: numba is installed and ``EPP_ROS_COMPILED`` is not 0.
COMPILED = (importlib.util.find_spec('numba') is not None
            and os.environ.get('EPP_ROS_COMPILED', '1') != '0')


def kernel(module):
    """Return the kernel ``module`` (a dotted name) where ``COMPILED``, else None."""
    return _imported(module) if COMPILED else None


@lru_cache(maxsize=None)
def _imported(module):
    return importlib.import_module(module)


def compiled(function):
    """
    Return ``function`` compiled: nopython, cached on disk, without the GIL.

    The first compile on a machine takes seconds; numba then loads it from its cache beside
    the module. Without the GIL a node's executor thread runs while its worker fits.
    numba's cache sees edits to a function's own file only: after editing a kernel that
    others call from other files (``model.compiled_boom``, ``model.compiled_nlos``'s
    loss), remove the callers' ``__pycache__`` too.
    """
    import numba
    return numba.njit(cache=True, nogil=True)(function)


def plain(array, dtype=float):
    """
    Return ``array`` as the kernels are compiled for it: of ``dtype``, C order, writeable.

    A copy only where it is not already. numba compiles a function again (seconds, on a
    frame) for each new type of argument, and read-only or strided arrays are new types.
    """
    if type(array) is np.ndarray and array.dtype == dtype:     # most: as they are, at once
        flags = array.flags
        if flags.c_contiguous and flags.writeable:
            return array
    return np.require(array, dtype=dtype, requirements='CW')
