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

"""The stamp rules shared by the estimator node and epp_bag eval."""
import math

from epp_ros.core.estimation.frame_policy import (ADMIT, CLOCK_JUMP, FramePolicy, MALFORMED,
                                                  OUT_OF_ORDER)
import numpy as np
import pytest


def test_stamps_must_increase_and_a_large_step_back_is_a_clock_jump():
    policy = FramePolicy(backward_jump=1.0)
    decisions = [policy.admit(t) for t in (100.0, 100.1, 100.05, 100.1, 100.2, 50.0, 50.1)]
    assert decisions == [ADMIT, ADMIT, OUT_OF_ORDER, OUT_OF_ORDER, ADMIT, CLOCK_JUMP, ADMIT]


@pytest.mark.parametrize('stamp', [0.0, -1.0, math.nan, math.inf, None, '1'])
def test_unset_or_impossible_stamps_are_malformed_and_change_nothing(stamp):
    policy = FramePolicy()
    assert policy.admit(10.0) == ADMIT
    assert policy.admit(stamp) == MALFORMED
    assert policy.admit(10.1) == ADMIT            # not a clock jump after a zero stamp


def test_the_jump_threshold_is_checked():
    with pytest.raises(ValueError, match='backward_jump'):
        FramePolicy(0.0)
    assert FramePolicy(np.float64(2.0)).backward_jump == 2.0
