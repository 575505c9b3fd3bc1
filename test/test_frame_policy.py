"""The stamp rules shared by the estimator node and epp_bag eval."""
import math

import numpy as np
import pytest

from epp_ros.core.frame_policy import ADMIT, CLOCK_JUMP, MALFORMED, OUT_OF_ORDER, FramePolicy


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
