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

"""The norms of many small vectors: numpy.linalg.norm's, to rounding."""
from epp_ros.core.model.vectors import norms
import numpy as np
import pytest


@pytest.mark.parametrize('shape', [(3,), (7, 3), (4, 5, 6, 3), (9, 2), (0, 3)])
def test_the_norms_are_numpys_to_rounding(shape):
    vectors = np.random.default_rng(len(shape)).normal(0.0, 30.0, shape)
    found = norms(vectors)
    assert found.shape == shape[:-1]
    np.testing.assert_allclose(found, np.linalg.norm(vectors, axis=-1), rtol=1e-15, atol=0)


def test_a_known_norm_and_non_finite_entries():
    assert norms(np.array([3.0, 4.0])) == 5.0
    found = norms(np.array([[np.nan, 0.0, 0.0], [np.inf, 1.0, 0.0]]))
    assert np.isnan(found[0]) and found[1] == np.inf
