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

"""A frame's bounds compiled (``compiled_bounds``) against ``frame_bounds``' numpy path."""
from epp_ros.core.estimation.bias_learning import bias_design
from epp_ros.core.model import bounds
from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation.simulate import random_posture, RangeNoise, truck_pump
from epp_ros.core.solvers import compiled
import numpy as np
import pytest

MODEL = truck_pump()


def _frame(rng, angles):
    """Residuals of a random posture: links dropped, a sigma per link; angle rows if asked."""
    slew, pitches, joints = random_posture(MODEL, rng)
    ranges = RangeNoise(sigma=0.1).apply(MODEL.ranges(joints), rng)[0]
    # Some links missing, most, or every one (the angle rows alone, or no row at all).
    ranges[rng.random(ranges.shape) < rng.choice([rng.uniform(0.0, 0.9), 1.0], p=[0.9, 0.1])] \
        = np.nan
    p = MODEL.n_sections
    tag_ranges = np.full((p, p), np.nan)
    measured = {}
    if angles:
        tag_ranges[0, 2] = np.linalg.norm(joints[0] - joints[2]) + 0.02
        measured = {'pitches': np.where(rng.random(p) < 0.5, pitches, np.nan), 'slew': slew}
    frame = Measurements(ranges, tag_ranges, measured.get('pitches', np.full(p, np.nan)),
                         measured.get('slew', np.nan))
    sigma = 0.1 * rng.uniform(0.5, 2.0, ranges.shape)
    return Residuals(MODEL, frame, SensorNoise(sigma, 0.03, 0.01, 0.01)), np.r_[slew, pitches]


def _common(residuals, psi):
    """Return a common bias for :func:`bounds.frame_bounds`: offset, slope, two anchors."""
    tags, anchors = np.nonzero(residuals.link_mask)
    joints = MODEL.forward_kinematics(psi[0], psi[1:])
    directions = joints[tags] - MODEL.anchors[anchors]
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    design = bias_design(residuals.measured[:tags.size], directions, anchors, (4, 5))
    return design, np.diag([0.04, 1e-4] + [0.01] * 6)


@pytest.mark.parametrize('angles', [False, True])
@pytest.mark.parametrize('biased', [False, True])
def test_the_compiled_bounds_are_numpys(monkeypatch, angles, biased):
    """
    The same bounds to 1e-9 of themselves, the same structure (infinite, nothing added).

    Where the widened bound is over a kilometre a link nothing checks makes it (its
    redundancy number near 0, divided by): the two paths round that differently, to
    1e-4 of itself, and the frame is unobservable either way.
    """
    rng = np.random.default_rng([11, angles, biased])
    kinds = set()
    for _ in range(60):
        residuals, psi = _frame(rng, angles)
        common = _common(residuals, psi) if biased else None
        monkeypatch.setattr(compiled, 'COMPILED', True)
        ours = bounds.frame_bounds(MODEL, residuals, psi, common)
        monkeypatch.setattr(compiled, 'COMPILED', False)
        reference = bounds.frame_bounds(MODEL, residuals, psi, common)
        np.testing.assert_allclose(ours[2], reference[2], rtol=1e-12, atol=1e-12)
        assert (ours[0] is ours[1]) == (reference[0] is reference[1])
        kinds.add((np.isinf(reference[0].rmse), reference[0] is reference[1]))
        for got, expected in zip(ours[:2], reference[:2]):
            assert np.isinf(got.rmse) == np.isinf(expected.rmse)
            if np.isfinite(expected.rmse):
                rtol = 1e-9 if expected.rmse < 1e3 else 1e-4
                assert got.rmse == pytest.approx(expected.rmse, rel=rtol)
                np.testing.assert_allclose(got.joint_covariance, expected.joint_covariance,
                                           rtol=rtol, atol=rtol * expected.rmse ** 2)
                scale = np.abs(expected.parameter_covariance).max()
                np.testing.assert_allclose(got.parameter_covariance,
                                           expected.parameter_covariance, rtol=rtol,
                                           atol=rtol * scale)
    # Widened, not determined and (with no common bias) the bound alone: each path taken.
    assert {(False, False), (True, True)} <= kinds
    assert biased or (False, True) in kinds
