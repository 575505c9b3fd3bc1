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

"""Every compiled kernel the methods run, compiled at once before the first frame."""
from epp_ros.core.model import bounds, nlos, plane
from epp_ros.core.solvers import point_newton
from epp_ros.core.solvers.compiled import kernel

from . import chain

__all__ = ['compile_fit', 'KERNELS']

#: The kernels' modules: the chain's and the tracker's fit, CEPP's Newton finish in the
#: points and its plane prediction, the NLOS loss of candidate positions, and the bounds
#: the integrity checks judge a frame by.
KERNELS = (chain.KERNEL, point_newton.KERNEL, plane.KERNEL, nlos.KERNEL, bounds.KERNEL)


def compile_fit():
    """
    Compile the fits now where they run compiled (``compiled.COMPILED``); return whether.

    Those of :data:`KERNELS`. The first compile on a machine takes about a minute; numba
    then loads them from its disk cache (a second or two). Called before the first frame
    where that frame's time matters.
    """
    for module in KERNELS:
        if kernel(module) is None:
            return False
        kernel(module).compile_now()
    return True
