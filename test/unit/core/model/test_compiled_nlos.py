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

"""The NLOS loss compiled (``compiled_nlos``) against ``LinkLoss``, its reference."""
from epp_ros.core.model import compiled_nlos
from epp_ros.core.model.nlos import LinkLoss, NlosMixture, range_excess
from epp_ros.core.solvers import compiled
import numpy as np
import pytest
from scipy.special import log_ndtr

MIXTURES = {'gaussian': NlosMixture(0.0, 1.0),
            'nlos': NlosMixture(0.1, 1.0),
            'nlos and outliers': NlosMixture(0.1, 0.6).judged(0.02)}


@pytest.fixture(params=['compiled', 'numpy'])
def path(request, monkeypatch):
    """Score candidates compiled (``compiled_nlos.tag_losses``), then in numpy."""
    monkeypatch.setattr(compiled, 'COMPILED', request.param == 'compiled')
    return request.param


def test_log_ndtr_is_scipys_from_deep_in_the_tail_to_one():
    z = np.r_[np.linspace(-80.0, 40.0, 4001), -37.0, -1.0, 0.0, 6.0]
    ours = np.array([compiled_nlos.log_ndtr(value) for value in z])
    np.testing.assert_allclose(ours, log_ndtr(z), rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize('name', ['nlos', 'nlos and outliers'])
def test_the_loss_is_the_link_losss_on_each_sign_of_excess(name):
    bound = MIXTURES[name].bind(np.array([0.05, 0.1, 0.3, 1.0]))
    terms = compiled_nlos.loss_terms(bound)
    for excess in (np.array([-40.0, -3.0, 0.5, 60.0]), np.array([0.0, 2.0, -0.2, 9.0])):
        cost, slope, _ = bound(excess)
        ours = np.array([compiled_nlos.link_loss(s, terms, i) for i, s in enumerate(excess)])
        np.testing.assert_allclose(ours[:, 0], cost, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(ours[:, 1], slope, rtol=1e-12, atol=1e-12)


def _scene(rng, q=4, m=7):
    """Anchors (m, 3), ranges (q, m) from a posture with noise, blocked and missing links."""
    anchors = rng.uniform(-6.0, 6.0, (m, 3))
    tags = rng.uniform(-20.0, 20.0, (q, 3))
    ranges = np.linalg.norm(tags[:, None] - anchors, axis=-1) + rng.normal(0.0, 0.1, (q, m))
    ranges[rng.random((q, m)) < 0.2] += rng.uniform(0.5, 5.0)
    ranges[rng.random((q, m)) < 0.2] = np.nan
    return anchors, tags, ranges


def _reference(loss, points, anchors, ranges, sigma):
    """Return the loss summed over anchors, from ``LinkLoss.__call__``; 0 where unheard."""
    excess = range_excess(points, anchors, ranges, sigma)
    return np.sum(np.where(np.isfinite(ranges), loss(excess)[0], 0.0), axis=-1)


@pytest.mark.parametrize('name', list(MIXTURES))
@pytest.mark.parametrize('per_link', [False, True])
def test_candidates_of_every_tag_are_scored_as_the_loss_scores_them(path, name, per_link):
    rng = np.random.default_rng([7, per_link, len(name)])
    for _ in range(5):
        anchors, tags, ranges = _scene(rng)
        sigma = rng.uniform(0.05, 0.4, ranges.shape) if per_link else np.float64(0.12)
        loss = MIXTURES[name].bind(sigma)
        points = tags + rng.normal(0.0, 2.0, (9, 2) + tags.shape)       # (9, 2, q, 3)
        full = np.broadcast_to(sigma, ranges.shape)
        expected = _reference(loss, points, anchors, ranges, full)
        got = loss.at_points(points, ranges, anchors)
        assert got.shape == (9, 2, len(tags))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize('name', list(MIXTURES))
@pytest.mark.parametrize('per_link', [False, True])
def test_candidates_named_by_tag_are_scored_with_that_tags_ranges(path, name, per_link):
    rng = np.random.default_rng([11, per_link, len(name)])
    anchors, tags, ranges = _scene(rng, q=5, m=6)
    sigma = rng.uniform(0.05, 0.4, ranges.shape) if per_link else np.float64(0.2)
    loss = MIXTURES[name].bind(sigma)
    which = rng.integers(0, len(tags), 40)
    points = tags[which] + rng.normal(0.0, 3.0, (40, 3))
    full = np.broadcast_to(sigma, ranges.shape)
    expected = _reference(MIXTURES[name].bind(full[which]), points, anchors, ranges[which],
                          full[which])
    np.testing.assert_allclose(loss.at_points(points, ranges, anchors, tags=which), expected,
                               rtol=1e-12, atol=1e-12)


def test_a_tag_at_its_measured_ranges_costs_nothing_and_an_unheard_tag_nothing(path):
    anchors = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 1.0], [4.0, 4.0, 8.0]])
    tags = np.array([[3.0, 2.0, 5.0], [1.0, -7.0, 2.0]])
    ranges = np.linalg.norm(tags[:, None] - anchors, axis=-1)
    ranges[1] = np.nan
    loss = MIXTURES['nlos and outliers'].bind(np.float64(0.1))
    cost = loss.at_points(np.stack([tags, tags + [0.0, 0.0, 1.0]]), ranges, anchors)
    np.testing.assert_allclose(cost[0], 0.0, atol=1e-12)
    assert cost[1, 0] > 1.0 and cost[1, 1] == 0.0


def test_a_non_finite_candidate_scores_nan_and_a_misshapen_loss_is_refused(path):
    anchors, tags, ranges = _scene(np.random.default_rng(3))
    loss = MIXTURES['nlos'].bind(np.full(ranges.shape, 0.1))
    points = tags.copy()
    points[1, 0] = np.nan
    with np.errstate(invalid='ignore'):
        cost = loss.at_points(points, np.nan_to_num(ranges, nan=5.0), anchors)
    assert np.isnan(cost[1]) and np.all(np.isfinite(np.delete(cost, 1)))
    with pytest.raises(ValueError, match='one sigma, or one per range'):
        loss.at_points(tags[:2], ranges[:2], anchors)


def test_a_loss_for_some_rows_has_the_constants_of_a_loss_bound_to_them():
    rng = np.random.default_rng(5)
    sigma = rng.uniform(0.05, 0.5, (4, 6))
    loss = LinkLoss(MIXTURES['nlos and outliers'], sigma)
    loss.at_zero        # computed before: taken with the rows
    rows = np.array([3, 0, 0, 2])
    taken, fresh = loss._rows(rows), LinkLoss(MIXTURES['nlos and outliers'], sigma[rows])
    excess = rng.normal(0.0, 3.0, (4, 6))
    for ours, theirs in zip(taken(excess), fresh(excess)):
        np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize('points, ranges, anchors, tags', [
    (np.zeros((2, 4, 2)), np.ones((4, 7)), np.zeros((7, 3)), None),   # not 3-D points
    (np.zeros((2, 3, 3)), np.ones((4, 7)), np.zeros((7, 3)), None),   # 3 tags for 4 rows
    (np.zeros((2, 4, 3)), np.ones((4, 7)), np.zeros((6, 3)), None),   # 6 anchors for 7
    (np.zeros((2, 4, 3)), np.ones(7), np.zeros((7, 3)), None),        # ranges of no tag
    (np.zeros((3, 3)), np.ones((4, 7)), np.zeros((7, 3)), [0, 4, 1]),   # no tag 4
    (np.zeros((3, 3)), np.ones((4, 7)), np.zeros((7, 3)), [0, -1, 1]),
    (np.zeros((3, 3)), np.ones((4, 7)), np.zeros((7, 3)), [0, 1]),      # a tag short
    (np.zeros((2, 3)), np.ones((4, 7)), np.zeros((7, 3)), [0.0, 1.0]),  # not indices
])
def test_misshapen_candidates_are_refused_never_read_past_their_arrays(
        path, points, ranges, anchors, tags):
    loss = MIXTURES['nlos'].bind(np.float64(0.1))
    with pytest.raises(ValueError, match='candidates: '):
        loss.at_points(points, ranges, anchors, tags=tags)


def test_no_candidates_score_nothing(path):
    anchors, tags, ranges = _scene(np.random.default_rng(9))
    loss = MIXTURES['nlos'].bind(np.float64(0.1))
    assert loss.at_points(np.zeros((0, 3)), ranges, anchors, tags=[]).shape == (0,)
    assert loss.at_points(np.zeros((0, len(tags), 3)), ranges, anchors).shape == (0, len(tags))


@pytest.mark.parametrize('name', list(MIXTURES))
def test_the_floor_is_the_same_compiled_and_in_numpy(name, monkeypatch):
    sigma = np.array([[0.02, 0.1, 0.3], [1.0, 0.05, 0.2]])
    priors = (None, np.array([[0.0, 0.3, 0.9], [0.5, 1e-3, 0.2]]))
    for prior in priors:
        compiled_floor = LinkLoss(MIXTURES[name], sigma, prior).floor
        monkeypatch.setattr(compiled, 'COMPILED', False)
        numpy_floor = LinkLoss(MIXTURES[name], sigma, prior).floor
        monkeypatch.setattr(compiled, 'COMPILED', True)
        assert compiled_floor.shape == sigma.shape and np.all(np.isfinite(compiled_floor))
        np.testing.assert_allclose(compiled_floor, numpy_floor, rtol=1e-12, atol=1e-12)
