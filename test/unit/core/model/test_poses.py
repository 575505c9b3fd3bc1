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

from epp_ros.core import PostureEstimator
from epp_ros.core.model.poses import boom_frames, boom_quaternions, rotation_to_quaternion
from epp_ros.core.simulation.simulate import random_posture, RangeNoise, truck_pump
import numpy as np
import pytest

BASE = np.array([0.0, 0.0, 3.5])


def check_frames(base, joints):
    rotations = boom_frames(base, joints)
    np.testing.assert_allclose(rotations @ rotations.transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), rotations.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0)
    sections = np.diff(np.vstack([base, joints]), axis=0)
    along = sections / np.linalg.norm(sections, axis=1, keepdims=True)
    np.testing.assert_allclose(rotations[1:, :, 0], along, atol=1e-12)   # x along section
    assert np.all(rotations[:, 2, 2] >= -1e-12)                         # z points up
    np.testing.assert_allclose(rotations[:, 2, 1], 0.0, atol=1e-12)     # y horizontal
    return rotations


def test_known_orientations():
    joints = np.array([[0.0, 3.0, 3.5], [0.0, 3.0, 7.5]])       # slewed to +y, then up
    rotations = check_frames(BASE, joints)
    np.testing.assert_allclose(rotations[0], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(boom_quaternions(BASE, joints)[0],
                               [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    np.testing.assert_allclose(rotations[2][:, 0], [0, 0, 1], atol=1e-12)


def test_noisy_estimates_folded_booms_and_a_vertical_boom():
    model = truck_pump()
    rng = np.random.default_rng(0)
    for _ in range(20):
        joints = random_posture(model, rng)[2]
        ranges, _ = RangeNoise(sigma=0.3).apply(model.ranges(joints), rng)
        check_frames(model.base, PostureEstimator(model, 'epp1').update(ranges))
    folded = model.forward_kinematics(0.4, np.radians([85.0, 120.0, 170.0, -100.0, -60.0]))
    check_frames(model.base, folded)
    check_frames(model.base, model.forward_kinematics(0.0, np.full(5, np.pi / 2)))


@pytest.mark.parametrize('seed', range(5))
def test_quaternions_round_trip(seed):
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    rotation = q * np.sign(np.diag(r))
    rotation *= np.linalg.det(rotation)
    x, y, z, w = rotation_to_quaternion(rotation)
    rebuilt = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(rebuilt, rotation, atol=1e-12)
    assert w >= 0


def test_quaternions_written_directly_are_the_frames():
    # boom_quaternions writes the frames' quaternions in closed form: the same rotations
    # as the general conversion, folded, vertical and turned-round booms included.
    model = truck_pump()
    rng = np.random.default_rng(3)
    postures = [random_posture(model, rng)[2] for _ in range(200)] + [
        model.forward_kinematics(0.4, np.radians([85.0, 120.0, 170.0, -100.0, -60.0])),
        model.forward_kinematics(0.0, np.full(5, np.pi / 2)),
        model.forward_kinematics(-2.0, np.full(5, -np.pi / 2)),
        model.forward_kinematics(np.pi - 1e-3, np.full(5, 0.3))]
    for joints in postures:
        general = rotation_to_quaternion(boom_frames(model.base, joints))
        direct = boom_quaternions(model.base, joints)
        assert np.all(direct[:, 3] >= 0)
        np.testing.assert_allclose(direct, general, atol=1e-12)
