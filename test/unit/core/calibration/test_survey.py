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

"""The anchor self-survey: what anchor-anchor ranges determine, and what they cannot."""
from epp_ros.core import BoomModel, survey_anchors, SurveyResult
from epp_ros.core.simulation.simulate import FieldEffects, FieldSimulator, truck_pump
import numpy as np
import pytest

#: Standard errors a statistic may be off by before a test calls it wrong.
TOLERANCE_SE = 5.0

#: Anchors 0-2 (not on a line) are on the truck; the others are set up on site.
FIXED = (0, 1, 2)


def scattered(count=8, heights=(0.0, 12.0), seed=0):
    """Return a boom with ``count`` anchors scattered around it: many pairs."""
    low, high = heights
    anchors = np.random.default_rng(seed).uniform([-15, -15, low], [15, 15, high], (count, 3))
    return BoomModel(np.full(5, 4.0), [0.0, 0.0, 3.5], anchors)


def site(model, seed, sigma=0.1, shift=0.3, offset=0.15, rounds=1, fixed=FIXED):
    """Return the simulator (the truth) and ``rounds`` rounds of anchor-anchor ranges."""
    moving = tuple(j for j in range(model.n_anchors) if j not in fixed)
    effects = FieldEffects(sigma=sigma, anchor_offset=offset, anchor_shift=shift,
                           moving_anchors=moving)
    simulator = FieldSimulator(model, effects, np.random.default_rng(seed))
    return simulator, np.array([simulator.anchor_ranges() for _ in range(rounds)])


def test_exact_recovery_without_noise():
    model = scattered()
    simulator, ranges = site(model, 1, sigma=0.0)
    # Told ranges this exact, the prior's pull on what they determine vanishes.
    result = survey_anchors(model, ranges, fixed_anchors=FIXED, sigma=1e-6)
    assert isinstance(result, SurveyResult) and result.success and result.converged
    np.testing.assert_allclose(result.anchors, simulator.true_anchors, atol=1e-6)
    np.testing.assert_allclose(result.anchor_offsets, simulator.anchor_offsets, atol=1e-6)
    np.testing.assert_array_equal(result.anchor_std[list(FIXED)], 0.0)
    assert result.residual_rms < 1e-6 and result.free == tuple(range(3, 8))
    assert result.rounds == 1 and result.pairs == 28
    # One round as a plain (m, m) array is the same survey.
    again = survey_anchors(model, ranges[0], fixed_anchors=FIXED, sigma=1e-6)
    np.testing.assert_allclose(again.anchors, result.anchors, atol=1e-9)


def test_turret_alone_leaves_a_rotation_the_configuration_resolves():
    model = truck_pump()
    simulator, ranges = site(model, 2, sigma=0.0, offset=0.0, fixed=(0,))
    result = survey_anchors(model, ranges, fixed_anchors=(0,), sigma=1e-6, offsets=False)
    # Every anchor-anchor distance is exact: only the rotation about anchor 0 is open.
    fitted = np.linalg.norm(result.anchors[:, None] - result.anchors[None], axis=-1)
    true = np.linalg.norm(simulator.true_anchors[:, None] - simulator.true_anchors[None],
                          axis=-1)
    np.testing.assert_allclose(fitted, true, atol=1e-6)
    assert result.status == 'poorly_determined' and not result.success
    assert 'rotation of the free anchors about fixed anchor 0' in result.message
    assert 'resolved only by its configured position' in result.message
    assert result.anchor_offset_std is None and not result.offsets_estimated
    np.testing.assert_array_equal(result.anchor_offsets, model.anchor_offsets)
    # Reported honestly: the rotation leaves the outriggers decimetres uncertain.
    assert np.linalg.norm(result.anchor_std[1:], axis=1).min() > 0.1


def test_coplanar_anchors_leave_the_height_poorly_determined():
    model = scattered(heights=(0.4, 0.6), seed=3)
    _, ranges = site(model, 4, rounds=20)
    result = survey_anchors(model, ranges, fixed_anchors=FIXED)
    assert result.status == 'poorly_determined'
    assert 'height' in result.message and 'coplanar' in result.message
    assert np.all(result.anchor_std[3:, 2] > result.anchor_std[3:, :2].max(axis=1))
    assert result.anchor_std[3:, 2].min() > 0.1


def test_noisy_surveys_lie_within_their_reported_uncertainty():
    """Over many sites the errors' chi-square per parameter averages 1."""
    model = scattered()
    trials, chi2, inside = 200, [], []
    for seed in range(trials):
        # Anchors and offsets drawn as the prior says: the posterior is then exact.
        simulator, ranges = site(model, [5, seed], shift=0.5, offset=0.5, rounds=3)
        result = survey_anchors(model, ranges, fixed_anchors=FIXED, nlos_fraction=0.0)
        assert result.converged
        error = np.r_[(result.anchors - simulator.true_anchors)[list(result.free)].ravel(),
                      result.anchor_offsets - simulator.anchor_offsets]
        chi2.append(error @ np.linalg.solve(result.covariance, error) / error.size)
        inside.append(np.abs(error) < 2 * np.sqrt(np.diag(result.covariance)))
    size = error.size
    assert abs(np.mean(chi2) - 1.0) < TOLERANCE_SE * np.sqrt(2.0 / (size * trials)) + 0.02
    coverage = np.mean(inside)
    assert abs(coverage - 0.9545) < TOLERANCE_SE * np.sqrt(0.9545 * 0.0455 / trials)


def test_a_blocked_link_is_discounted():
    model = scattered()
    _, ranges = site(model, 6, rounds=10)
    clean = survey_anchors(model, ranges, fixed_anchors=FIXED)
    ranges[:, 3, 5] += 2.0      # one direction of one pair, blocked every round
    robust = survey_anchors(model, ranges, fixed_anchors=FIXED)
    plain = survey_anchors(model, ranges, fixed_anchors=FIXED, nlos_fraction=0.0)
    assert robust.nlos[:, 3, 5].min() > 0.9 and robust.nlos[:, 5, 3].max() < 0.5

    def moved(result):      # from the survey without the blocked link, in its stds
        return np.max(np.abs(result.anchors - clean.anchors)[3:] / clean.anchor_std[3:])
    assert moved(robust) < 1.5 and moved(plain) > 3 * moved(robust)


@pytest.mark.parametrize('ranges, message', [
    (np.zeros((2, 6, 5)), r'shape \(K, 6, 6\) with K >= 1'),
    (np.zeros(6), r'shape \(K, 6, 6\) with K >= 1'),
    (np.zeros((0, 6, 6)), r'shape \(K, 6, 6\) with K >= 1'),
    (np.zeros((3, 1, 1)), r'shape \(K, 6, 6\) with K >= 1'),
    ('ranges', r'shape \(K, 6, 6\) with K >= 1'),
    (np.full((3, 6, 6), np.nan), 'no finite range between two anchors'),
])
def test_bad_anchor_ranges_are_refused_with_one_clear_message(ranges, message):
    with pytest.raises(ValueError, match=message):
        survey_anchors(truck_pump(), ranges)


def test_an_anchor_nobody_heard_cannot_be_surveyed():
    model = truck_pump()
    _, ranges = site(model, 7, fixed=(0,))
    ranges[:, 3, :] = ranges[:, :, 3] = np.nan
    with pytest.raises(ValueError, match=r'anchor\(s\) \[3\]'):
        survey_anchors(model, ranges)
    with pytest.raises(ValueError, match='fixed_anchors'):
        survey_anchors(model, ranges, fixed_anchors=(0, 9))
    with pytest.raises(ValueError, match='sigma'):
        survey_anchors(model, ranges, fixed_anchors=(0, 3), sigma=0.0)
