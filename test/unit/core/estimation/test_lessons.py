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

"""What a frame teaches the learners is learned after its posture: ``PostureEstimator.settle``."""
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.bias_learning import REFERENCE_RANGE
from epp_ros.core.simulation.simulate import (FieldEffects, FieldSimulator, truck_outriggers,
                                              truck_pump, WorkingMotion)
import numpy as np
import pytest

MODEL = truck_pump()
MOVING = truck_outriggers(MODEL)


def learning_frames(seconds=20.0, seed=4):
    """Frames that teach every learner: a common bias growing with range, outriggers moved."""
    curve = tuple((r, 0.2 + 0.006 * (r - REFERENCE_RANGE)) for r in (0.0, 100.0))
    effects = FieldEffects(sigma=0.05, bias_curve=curve, anchor_shift=0.2,
                           moving_anchors=MOVING, nlos_fraction=0.05)
    rng = np.random.default_rng(seed)
    simulator = FieldSimulator(MODEL, effects, rng)
    motion = WorkingMotion(MODEL, rng)
    return [simulator.frame(motion, stamp).inputs() for stamp in np.arange(0.0, seconds, 0.1)]


def estimator(method):
    return PostureEstimator(MODEL, method, sigma=0.1, learn_anchors=True, moving_anchors=MOVING)


def outputs(estimator):
    result = estimator.last_diagnostics
    return (result['status'], result['estimate'].copy(), result['predicted_rmse'])


def learned(estimator):
    return (estimator.noise, estimator.range_bias.copy(), estimator.anchor_shifts.copy(),
            estimator.integrity.common_covariance.copy())


def assert_same(first, second):
    for a, b in zip(first, second):
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b


@pytest.mark.parametrize('method', ['chain', 'cepp', 'track'])
def test_when_a_frame_is_learned_from_changes_no_frame(method):
    """Settled at once, by the next update, or by reading: the same frames, bit for bit."""
    frames = learning_frames()
    at_once, by_update, by_reading = (estimator(method) for _ in range(3))
    changes = 0
    for frame in frames:
        noise = at_once.noise
        for each in (at_once, by_update, by_reading):
            each.update(**frame)
        # Each frame is judged with the noise learned before it, and reports that.
        assert at_once.last_diagnostics['noise'] == noise
        at_once.settle()
        at_once.settle()                            # a lesson is learned once
        changes += at_once.noise != noise
        learned(by_reading)
        assert_same(outputs(at_once), outputs(by_update))
        assert_same(outputs(at_once), outputs(by_reading))
    assert changes >= 3                             # the learners did learn, frame by frame
    assert_same(learned(at_once), learned(by_update))
    assert_same(learned(at_once), learned(by_reading))
    assert np.abs(at_once.range_bias[0] - 0.2) < 0.1 and np.any(at_once.anchor_shifts)


def test_what_the_caller_changes_of_what_it_was_handed_is_not_learned():
    """The lesson keeps its own copies of the posture, the angles and the links set aside."""
    frames = learning_frames(seconds=10.0)
    kept, spoiled = estimator('track'), estimator('track')
    for frame in frames:
        kept.update(**frame)
        returned = spoiled.update(**frame)
        assert_same(outputs(kept), outputs(spoiled))
        result = spoiled.last_diagnostics
        for array in (returned, result['estimate'], result['angles'][1],
                      result.get('timed_joints'), result.get('nlos_links'),
                      result.get('outlier_links')):
            if array is not None:
                array[...] = 1.0 if array.dtype == bool else 1e6
    assert_same(learned(kept), learned(spoiled))


def test_reconfiguring_and_resetting_learn_the_last_frame_first():
    frames = learning_frames(seconds=6.0)
    first, second = estimator('chain'), estimator('chain')
    for frame in frames:
        first.update(**frame)
        second.update(**frame)
        first.settle()
    first.reset()
    first.reconfigure(lowest_joint=-1.0)
    second.reset()                  # learns the last frame, as settling first did
    second.reconfigure(lowest_joint=-1.0)
    assert_same(learned(first), learned(second))
    first.update(**frames[0])
    second.update(**frames[0])
    assert_same(outputs(first), outputs(second))
