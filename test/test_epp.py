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

"""The NEDM estimators' NLOS reweighting (core.epp); the paper's H = 1 kept as an option."""
from epp_ros.core import PostureEstimator
from epp_ros.core.epp import CEPP, EPP1, EPP2
from epp_ros.core.measurements import Measurements
from epp_ros.core.simulate import truck_pump
import numpy as np
import pytest

MODEL = truck_pump()
TRUTH = MODEL.forward_kinematics(0.4, np.radians([50.0, 25.0, 5.0, -20.0, -45.0]))
#: Last frame's posture: the warm start.
PRIOR = MODEL.forward_kinematics(0.37, np.radians([51.0, 24.0, 6.0, -21.0, -44.0]))
#: One blocked link on each tag, metres too long.
BLOCKED = (np.array([0, 1, 2, 3, 4]), np.array([1, 4, 0, 5, 2]))
EXCESS = np.array([1.0, 1.5, 0.8, 2.0, 1.2])
#: CEPP's estimate of ``frame()`` from ``PRIOR`` before the reweighting existed (H = 1).
PAPER_CEPP = np.array([[5.6313, 2.682934, 9.987706],
                       [11.060879, 5.269761, 13.569325],
                       [17.371237, 8.27622, 13.944269],
                       [25.050595, 11.934914, 11.004639],
                       [30.815651, 14.681573, 4.662716]])


def frame(nlos=True, sigma=0.1):
    """Return the ranges to ``TRUTH`` with Gaussian noise, and the NLOS excesses if asked."""
    ranges = MODEL.ranges(TRUTH) + np.random.default_rng(2026).normal(0.0, sigma, (5, 6))
    if nlos:
        ranges[BLOCKED] += EXCESS
    return Measurements.clean(MODEL, ranges)[0]


def rmse(joints):
    return float(np.sqrt(np.mean(np.sum((joints - TRUTH) ** 2, axis=1))))


def test_blocked_links_are_discounted():
    paper, paper_info = CEPP(MODEL, irls_iterations=0).solve(frame(), PRIOR)
    joints, info = CEPP(MODEL).solve(frame(), PRIOR)
    assert rmse(joints) < 0.3 < 1.0 < rmse(paper)
    weights = info['link_weights']
    assert weights.shape == (5, 6)
    blocked = np.zeros((5, 6), bool)
    blocked[BLOCKED] = True
    assert np.all(weights[blocked] < 0.2) and np.all(weights[~blocked] > 0.9)
    assert 'link_weights' not in paper_info and paper_info['irls_iterations'] == 0
    np.testing.assert_allclose(MODEL.section_lengths(joints), MODEL.arm_lengths, atol=1e-6)


def test_irls_iterations_0_is_the_papers_cepp():
    joints, _ = CEPP(MODEL, irls_iterations=0).solve(frame(), PRIOR)
    np.testing.assert_allclose(joints, PAPER_CEPP, atol=1e-4)
    # Plain least squares weights every link 1: the reweighting path then is H = 1 too.
    gaussian, info = CEPP(MODEL, nlos_fraction=0.0).solve(frame(), PRIOR)
    np.testing.assert_array_equal(gaussian, joints)
    assert np.all(info['link_weights'] == 1.0) and info['irls_iterations'] == 0


def test_exact_ranges_are_not_reweighted():
    for prior in (PRIOR, TRUTH):
        paper, _ = CEPP(MODEL, irls_iterations=0).solve(frame(False, 0.0), prior)
        joints, info = CEPP(MODEL, irls_iterations=3).solve(frame(False, 0.0), prior)
        np.testing.assert_allclose(joints, paper, atol=1e-6)
        np.testing.assert_allclose(joints, TRUTH, atol=1e-6)
        np.testing.assert_array_equal(info['link_weights'], 1.0)
        assert info['irls_iterations'] == 0


def test_line_of_sight_noise_is_weighted_as_the_paper_does():
    """Links a few sigmas long are barely discounted: the answer moves by millimetres."""
    paper, _ = CEPP(MODEL, irls_iterations=0).solve(frame(False), PRIOR)
    joints, info = CEPP(MODEL).solve(frame(False), PRIOR)
    assert np.abs(joints - paper).max() < 0.01
    assert info['link_weights'].min() > 0.8


def test_epp1_and_epp2_are_the_papers_unless_asked():
    for cls in (EPP1, EPP2):
        assert cls(MODEL).irls_iterations == 0
        paper, info = cls(MODEL).solve(frame(), PRIOR)
        joints, _ = cls(MODEL, irls_iterations=2).solve(frame(), PRIOR)
        assert 'link_weights' not in info
        assert rmse(joints) < 0.5 * rmse(paper)


def test_tune_changes_the_weighting():
    method = CEPP(MODEL)
    method.tune(nlos_fraction=0.0)              # Gaussian: every weight 1
    joints, info = method.solve(frame(), PRIOR)
    np.testing.assert_allclose(joints, PAPER_CEPP, atol=1e-4)
    method.tune(nlos_fraction=0.1, sigma=5.0)   # a sigma that explains 2 m
    assert np.all(method.solve(frame(), PRIOR)[1]['link_weights'] == 1.0)
    method.tune(sigma=0.1)
    assert (method.sigma, method.eta, method.nlos.fraction, method.nlos.gamma) == (
        0.1, 0.0, 0.1, 1.0)
    assert rmse(method.solve(frame(), PRIOR)[0]) < 0.3


@pytest.mark.parametrize('name, value', [('sigma', -0.1), ('sigma', float('nan')),
                                         ('sigma', 'x'), ('sigma', 0.0), ('eta', -0.1),
                                         ('eta', True), ('nlos_fraction', 1.0),
                                         ('nlos_gamma', 0.0)])
def test_tune_checks_its_inputs(name, value):
    for method in (CEPP(MODEL), EPP2(MODEL)):
        with pytest.raises(ValueError, match=f'^{name}'):
            method.tune(**{name: value})
        assert (method.sigma, method.eta, method.nlos.fraction, method.nlos.gamma) == (
            0.1, 0.0, 0.1, 1.0)


@pytest.mark.parametrize('value', [-1, 1.5, True, None])
def test_irls_iterations_is_checked(value):
    with pytest.raises(ValueError, match='irls_iterations'):
        CEPP(MODEL, irls_iterations=value)
    with pytest.raises(ValueError, match='irls_iterations'):
        PostureEstimator(MODEL, 'cepp', irls_iterations=value)


def test_estimator_passes_the_noise_and_reports_the_weights():
    for irls_iterations in (0, 2):
        estimator = PostureEstimator(MODEL, 'cepp', sigma=0.1, nlos_fraction=0.2,
                                     irls_iterations=irls_iterations)
        estimator.update(MODEL.ranges(PRIOR), stamp=0.0)
        estimator.update(frame().ranges, stamp=1.0)
        diagnostics = estimator.last_diagnostics
        if irls_iterations:
            assert diagnostics['valid'] and rmse(diagnostics['estimate']) < 0.3
            assert diagnostics['link_weights'][BLOCKED].max() < 0.2
        else:
            assert 'link_weights' not in diagnostics
