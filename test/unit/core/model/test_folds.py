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

"""The one home of folds: reflections, their two forms, the tip's circle and its minima."""
from epp_ros.core.estimation.methods import angles_from_joints
from epp_ros.core.model.folds import (fold_alternatives, folded_angles, keep_folds, reflect,
                                      tip_circle, tip_minima, TIP_PITCHES)
from epp_ros.core.simulation import truck_pump
import numpy as np

MODEL = truck_pump()
PSI = np.r_[0.4, np.radians([50.0, 25.0, 5.0, -20.0, -45.0])]
JOINTS = MODEL.forward_kinematics(PSI[0], PSI[1:])


def test_a_fold_keeps_both_section_lengths_and_every_other_joint():
    folded = fold_alternatives(MODEL, JOINTS)
    assert folded.shape == (MODEL.n_sections - 1, 3)
    for k, position in enumerate(folded):
        moved = JOINTS.copy()
        moved[k] = position
        np.testing.assert_allclose(MODEL.section_lengths(moved), MODEL.arm_lengths, atol=1e-9)
        assert np.linalg.norm(position - JOINTS[k]) > 0.1        # none of these is straight
    # Folding twice is the identity.
    for k in range(MODEL.n_sections - 1):
        moved = JOINTS.copy()
        moved[k] = folded[k]
        np.testing.assert_allclose(fold_alternatives(MODEL, moved)[k], JOINTS[k], atol=1e-9)


def test_the_fold_in_angles_is_the_fold_in_space():
    for k, psi in enumerate(folded_angles(MODEL, PSI)):
        joints = MODEL.forward_kinematics(psi[0], psi[1:])
        expected = JOINTS.copy()
        expected[k] = fold_alternatives(MODEL, JOINTS)[k]
        np.testing.assert_allclose(joints, expected, atol=1e-9)
        np.testing.assert_allclose(angles_from_joints(MODEL, joints)[0], PSI[0], atol=1e-9)


def test_reflect_works_on_stacks_in_any_dimension():
    points = np.array([[1.0, 1.0], [0.0, 2.0]])
    inner, outer = np.zeros((2, 2)), np.array([[2.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(reflect(points, inner, outer), [[1.0, -1.0], [0.0, 2.0]])


def test_the_tip_circle_is_the_tip_section_round_its_hinge_in_the_plane():
    grid, ends = tip_circle(MODEL, JOINTS[-2], PSI[0])
    assert grid.shape == (TIP_PITCHES,) and ends.shape == (TIP_PITCHES, 3)
    np.testing.assert_allclose(np.linalg.norm(ends - JOINTS[-2], axis=1), MODEL.arm_lengths[-1])
    nearest = np.argmin(np.abs(np.angle(np.exp(1j * (grid - PSI[-1])))))
    assert np.linalg.norm(ends[nearest] - JOINTS[-1]) < MODEL.arm_lengths[-1] * np.pi / 72 + 1e-9
    horizontal = ends[:, :2] - JOINTS[-2, :2]           # along the slew: in the plane
    across = horizontal[:, 0] * np.sin(PSI[0]) - horizontal[:, 1] * np.cos(PSI[0])
    np.testing.assert_allclose(across, 0.0, atol=1e-9)
    _, each = tip_circle(MODEL, JOINTS[:3], PSI[0], section=2)      # a circle per hinge
    assert each.shape == (3, TIP_PITCHES, 3)
    for hinge, circle in zip(JOINTS[:3], each):
        np.testing.assert_array_equal(circle, tip_circle(MODEL, hinge, PSI[0], section=2)[1])


def test_tip_minima_are_the_circles_local_minima_lowest_first_where_away():
    angle = np.linspace(-np.pi, np.pi, 12, endpoint=False)
    loss = np.cos(2 * angle) + 0.1 * np.sin(angle)      # minima at -pi/2 (lower) and pi/2
    found = tip_minima(loss, np.ones(12, bool))
    assert list(found) == [3, 9]
    assert list(tip_minima(loss, np.arange(12) != found[0])) == [found[1]]
    assert tip_minima(np.ones(4), np.zeros(4, bool)).size == 0


def _reflected(chain, i):
    """Chain point ``i`` reflected across the line through its neighbours."""
    inner, outer = chain[i - 1], chain[i + 1]
    axis = (outer - inner) / np.linalg.norm(outer - inner)
    offset = chain[i] - inner
    return inner + 2.0 * (offset @ axis) * axis - offset


def test_keep_folds_restores_the_reference_fold_of_free_joints_only():
    pivot = np.array([0.5, 2.0])
    reference = np.array([[3.0, 6.0], [8.0, 7.0], [12.0, 4.0], [15.0, 0.0]])
    coords = reference.copy()
    coords[1] = _reflected(np.vstack([pivot, reference]), 2)     # joint 2 folded over
    free = np.array([False, True, False, False])
    kept, folded = keep_folds(coords, reference, pivot, free)
    np.testing.assert_allclose(kept, reference, atol=1e-12)
    np.testing.assert_array_equal(folded, [False, True, False, False])
    heard, folded = keep_folds(coords, reference, pivot, np.zeros(4, bool))
    np.testing.assert_array_equal(heard, coords)                # heard: its ranges decide
    assert not folded.any()
    # A straight reference has no fold to keep; a run of free joints is left alone.
    straight = np.array([[3.0, 6.0], [5.5, 10.0], [12.0, 4.0], [15.0, 0.0]])
    straight[1] = 0.5 * (straight[0] + straight[2])
    assert not keep_folds(coords, straight, pivot, free)[1].any()
    assert not keep_folds(coords, reference, pivot, [False, True, True, False])[1].any()
