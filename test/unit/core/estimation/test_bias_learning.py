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

"""The range bias common to all links, learned while running (core.bias_learning)."""
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.bias_learning import BiasLearner, REFERENCE_RANGE
from epp_ros.core.simulation.simulate import (FieldEffects, FieldSimulator, simulate_field,
                                              truck_outriggers, truck_pump, WorkingMotion)
import numpy as np
import pytest

MODEL = truck_pump()


def biased_frames(offset, slope, seconds=40.0, seed=3, link_offset=0.0):
    """Frames of the working cycle whose every range is long by offset + slope (r - r0)."""
    curve = tuple((r, offset + slope * (r - REFERENCE_RANGE)) for r in (0.0, 100.0))
    effects = FieldEffects(sigma=0.05, bias_curve=curve, link_offset=link_offset)
    rng = np.random.default_rng(seed)
    return simulate_field(MODEL, WorkingMotion(MODEL, rng), seconds, effects, rng)


def run(estimator, frames):
    """Return each frame's mean squared joint error (valid frames), the last diagnostics."""
    squared = []
    for frame in frames:
        estimator.update(**frame.inputs())
        result = estimator.last_diagnostics
        if result['valid']:
            squared.append(np.mean(np.sum((result['estimate'] - frame.joints) ** 2, axis=1)))
    return np.array(squared), estimator.last_diagnostics


@pytest.mark.parametrize('offset, slope', [(0.3, 0.0), (0.2, 0.008), (-0.15, 0.004)])
def test_a_common_bias_is_learned_to_its_stated_uncertainty(offset, slope):
    # Told that the links have no bias of their own (these have none): nothing floors
    # what frames tell.
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05, link_bias_std=0.0)
    squared, _ = run(estimator, biased_frames(offset, slope))
    learned = estimator.range_bias
    covariance = estimator.integrity.common_covariance
    error = learned - [offset, slope]
    # The estimate's own uncertainty, as a z-score of the pair: chi-square(2) < 18.4 but
    # once in 10,000 draws.
    assert error @ np.linalg.solve(covariance, error) < 18.4
    assert abs(error[0]) < 0.03 and abs(error[1]) < 0.002
    # What is still unknown has shrunk from the prior's 0.25 m to centimetres.
    assert np.sqrt(covariance[0, 0]) < 0.03


def test_learning_the_bias_takes_most_of_its_error_away():
    frames = biased_frames(0.3, 0.008)
    learned, _ = run(PostureEstimator(MODEL, 'chain', sigma=0.05), frames)
    fixed, last = run(PostureEstimator(MODEL, 'chain', sigma=0.05, learn_noise=False), frames)
    late = slice(len(learned) // 2, None)            # once learned
    assert np.sqrt(np.mean(learned[late])) < 0.5 * np.sqrt(np.mean(fixed[-len(learned[late]):]))
    # Unlearned, the fit is off by the bias it absorbed, and says so.
    assert last['predicted_rmse'] >= np.sqrt(fixed[-1]) / 3


def test_unbiased_ranges_learn_no_bias_and_a_told_zero_is_kept():
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05)
    run(estimator, biased_frames(0.0, 0.0, seconds=20.0))
    learned, covariance = estimator.range_bias, estimator.integrity.common_covariance
    assert learned @ np.linalg.solve(covariance, learned) < 18.4
    told = PostureEstimator(MODEL, 'chain', sigma=0.05, common_bias_std=0.0,
                            bias_slope_std=0.0)
    run(told, biased_frames(0.3, 0.0, seconds=5.0))
    assert np.all(told.range_bias == 0.0) and not told.integrity.common_covariance.any()


def test_each_links_own_bias_is_a_floor_under_what_frames_tell():
    # Biases of each link's own do not average over frames: the learned common part keeps
    # their share of its uncertainty, and its error stays within it.
    frames = biased_frames(0.2, 0.0, seconds=40.0, link_offset=0.1)
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05, link_bias_std=0.1)
    run(estimator, frames)
    estimator.settle()                      # the last frame learned, as the learner is read
    learner = estimator._learned.bias_learner
    assert learner.floor()[0, 0] > 0
    assert np.all(np.diag(estimator.integrity.common_covariance) >= np.diag(learner.floor()))
    error = estimator.range_bias[0] - 0.2
    assert abs(error) < 4 * np.sqrt(estimator.integrity.common_covariance[0, 0])


def test_a_frame_with_too_few_links_teaches_nothing():
    learner = BiasLearner(0.25, 0.01, 0.1, 6)
    jacobian = np.eye(6)[:, :4]
    assert not learner.observe(jacobian, np.full(6, 0.1), np.zeros(6), np.full(6, 10.0),
                               np.arange(6))
    assert learner.frames == 0 and not learner.estimate.any()


def moved_outriggers(seconds=60.0, seed=5, shift=0.2):
    """Return the true anchors and the frames of a pump whose outriggers stand elsewhere."""
    effects = FieldEffects(sigma=0.05, anchor_shift=shift, moving_anchors=truck_outriggers(MODEL))
    rng = np.random.default_rng(seed)
    simulator = FieldSimulator(MODEL, effects, rng)
    motion = WorkingMotion(MODEL, rng)
    frames = [simulator.frame(motion, stamp) for stamp in np.arange(0.0, seconds, 0.1)]
    return simulator.true_anchors, frames


def test_outriggers_that_stand_elsewhere_are_learned_to_their_stated_uncertainty():
    true_anchors, frames = moved_outriggers()
    moving = truck_outriggers(MODEL)
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05, link_bias_std=0.0,
                                 anchor_std=0.1, learn_anchors=True, moving_anchors=moving)
    squared, diagnostics = run(estimator, frames)
    shift = (true_anchors - MODEL.anchors)[list(moving)]
    assert np.min(np.linalg.norm(shift, axis=1)) > 0.1      # the case moves every one
    learned = estimator.anchor_shifts
    covariance = estimator.integrity.common_covariance[2:, 2:]
    error = (learned - shift).ravel()
    # The shifts' own uncertainty, as one z-score: chi-square(12) < 36.1 but once in 3,000.
    assert error @ np.linalg.solve(covariance, error) < 36.1
    assert np.sqrt(np.mean(error ** 2)) < 0.02
    assert set(diagnostics['anchor_shifts']) == set(moving)
    # Taken off the ranges, the shifts leave the boom at the noise's accuracy.
    late = squared[len(squared) // 2:]
    assert np.sqrt(np.mean(late)) < 0.15


def test_outriggers_not_learned_publish_nothing_far_off_and_say_how_unsure_they_are():
    # The defaults: the outriggers may stand 0.1 m per axis off, counted, not learned. They
    # stand twice that off: what the frames show of the shifts widens what is counted.
    true_anchors, frames = moved_outriggers(seconds=30.0, shift=0.2)
    told = PostureEstimator(MODEL, 'chain', sigma=0.05, moving_anchors=truck_outriggers(MODEL))
    ignorant = PostureEstimator(MODEL, 'chain', sigma=0.05, anchor_std=0.0,
                                moving_anchors=truck_outriggers(MODEL))
    confident = 0               # frames the ignorant one publishes > 1 m off, saying < 1/3
    for frame in frames:
        told.update(**frame.inputs())
        ignorant.update(**frame.inputs())
        said, unsaid = told.last_diagnostics, ignorant.last_diagnostics
        # The same fits: considering the shifts changes only the stds.
        assert np.array_equal(said['estimate'], unsaid['estimate'])
        assert said['valid'] == unsaid['valid']
        assert not np.any(np.isnan(said['joint_std']))
        assert said['predicted_rmse'] > unsaid['predicted_rmse']
        error = np.sqrt(np.mean(np.sum((said['estimate'] - frame.joints) ** 2, axis=1)))
        if said['valid']:
            assert error < 1.0 or said['predicted_rmse'] > error / 3
            confident += error >= 1.0 and unsaid['predicted_rmse'] <= error / 3
    # Nothing taken off the ranges; what the frames show of the shifts is reported.
    assert not told.anchor_shifts.any()
    moving = list(truck_outriggers(MODEL))
    shift = (true_anchors - MODEL.anchors)[moving]
    seen = np.array([said['anchor_shifts'][j] for j in moving])      # at the last frame
    for shifts in (seen, told.seen_anchor_shifts):
        assert np.sqrt(np.mean((shifts - shift) ** 2)) < 0.05 < np.sqrt(np.mean(shift ** 2))
    # The case is one where the stds without the shifts say too little.
    assert confident > 0


def test_no_moving_anchor_keeps_the_common_bias_alone_and_no_anchor_std_adds_nothing():
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05)
    assert estimator.anchor_shifts.shape == (0, 3)
    assert estimator.integrity.common_covariance.shape == (2, 2)
    # Moving anchors neither learned nor considered: the same postures and stds.
    _, frames = moved_outriggers(seconds=10.0)
    fixed = PostureEstimator(MODEL, 'chain', sigma=0.05, anchor_std=0.0, learn_anchors=True,
                             moving_anchors=truck_outriggers(MODEL))
    for frame in frames:
        fixed.update(**frame.inputs())
        estimator.update(**frame.inputs())
        assert np.array_equal(fixed.last_diagnostics['estimate'],
                              estimator.last_diagnostics['estimate'])
        assert fixed.last_diagnostics['predicted_rmse'] == pytest.approx(
            estimator.last_diagnostics['predicted_rmse'], rel=1e-9)
    assert not fixed.anchor_shifts.any() and fixed.anchor_shifts.shape == (4, 3)
    with pytest.raises(ValueError, match='moving_anchors'):
        PostureEstimator(MODEL, 'chain', moving_anchors=[MODEL.n_anchors])
    with pytest.raises(ValueError, match='anchor_std'):
        PostureEstimator(MODEL, 'chain', anchor_std=-0.1)
    with pytest.raises(ValueError, match='learn_anchors: must be true or false'):
        PostureEstimator(MODEL, 'chain', learn_anchors='yes')


def one_frame(learner, shift, seed=0):
    """Show ``learner`` one frame (4 tags, 3 anchors) whose anchor 1 stands ``shift`` off."""
    rng = np.random.default_rng(seed)
    tags = rng.uniform(-10.0, 10.0, (4, 3)) + [0.0, 0.0, 15.0]
    anchors = rng.uniform(-5.0, 5.0, (3, 3))
    units = tags[:, None] - anchors
    distances = np.linalg.norm(units, axis=-1)
    units /= distances[..., None]
    bias = np.zeros((4, 3))
    bias[:, 1] = -units[:, 1] @ shift
    left = bias - learner.correction(distances, units)     # once what it learned is off
    sigma = np.full(12, 0.05)
    # A fit that moves nothing: its Jacobian spans none of the bias's directions.
    jacobian = np.zeros((12, 1))
    assert learner.observe(jacobian, sigma, -left.ravel() / sigma, distances.ravel(),
                           np.arange(12), units.reshape(-1, 3))


def test_a_considered_shift_stays_zero_and_counts_what_frames_show():
    considered = BiasLearner(0.25, 0.01, 0.0, 12, anchor_std=0.1, moving=(1,), n_anchors=3)
    learned = BiasLearner(0.25, 0.01, 0.0, 12, anchor_std=0.1, moving=(1,), n_anchors=3,
                          learn_anchors=True)
    for learner in (considered, learned):
        np.testing.assert_allclose(np.diag(learner.covariance())[2:], 0.01)
    shift = np.array([0.3, -0.2, 0.1])
    for seed in range(20):
        one_frame(considered, shift, seed)
        one_frame(learned, shift, seed)
    # Counted, not learned: nothing taken off the ranges, and its second moment counted,
    # the shift the frames show squared plus what is still unknown of it.
    assert not considered.anchor_shifts.any()
    np.testing.assert_allclose(learned.anchor_shifts[0], shift, atol=0.01)
    unknown = np.diag(learned.covariance())[2:]
    assert np.all(unknown < 0.01)
    np.testing.assert_allclose(np.diag(considered.covariance())[2:], shift ** 2 + unknown,
                               atol=0.01)


def test_a_frames_reported_bias_stays_what_it_was_at_that_frame():
    estimator = PostureEstimator(MODEL, 'chain', sigma=0.05)
    frames = biased_frames(0.3, 0.0, seconds=10.0)
    estimator.update(**frames[40].inputs())
    reported = estimator.last_diagnostics['range_bias']
    kept = reported.copy()
    for frame in frames[41:]:
        estimator.update(**frame.inputs())
    assert np.array_equal(reported, kept) and not np.array_equal(estimator.range_bias, kept)
