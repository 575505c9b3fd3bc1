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

from epp_ros.core.simulate import random_posture, RangeNoise, truck_pump, working_cycle, xie3dim
import numpy as np
import pytest


def test_xie3dim_lengths_and_base_anchor():
    model, joints = xie3dim()
    np.testing.assert_allclose(model.section_lengths(joints), model.arm_lengths)
    assert model.base_anchor() == 0 and model.n_sections == 5 and model.n_anchors == 4


def test_truck_anchors_span_space_and_include_the_pivot():
    for count in range(4, 8):
        model = truck_pump(n_anchors=count)
        assert model.base_anchor() == 0
        assert np.linalg.matrix_rank(model.anchors - model.anchors.mean(0)) == 3
    with pytest.raises(ValueError, match='n_anchors'):
        truck_pump(n_anchors=9)


def test_random_postures_stay_above_ground():
    model = truck_pump()
    rng = np.random.default_rng(0)
    for _ in range(50):
        slew, pitches, joints = random_posture(model, rng, min_height=0.5)
        assert -np.pi <= slew < np.pi and joints[:, 2].min() >= 0.5
        np.testing.assert_allclose(joints, model.forward_kinematics(slew, pitches))


def test_noise_model_statistics():
    rng = np.random.default_rng(1)
    ranges = np.full((200, 200), 10.0)
    noisy, nlos = RangeNoise(sigma=0.3).apply(ranges, rng)
    assert abs(np.mean(noisy - ranges)) < 0.01 and abs(np.std(noisy - ranges) - 0.3) < 0.01
    assert not nlos.any()
    noisy, _ = RangeNoise(eta=0.05).apply(ranges, rng)
    assert abs(np.std(noisy - ranges) - 0.5) < 0.02                 # d * eta
    noisy, nlos = RangeNoise(nlos_fraction=0.2, nlos_gamma=2.0).apply(ranges, rng)
    assert abs(nlos.mean() - 0.2) < 0.01
    excess = (noisy - ranges)[nlos]
    assert excess.min() >= 0 and abs(excess.mean() - 2.0) < 0.05
    np.testing.assert_array_equal(noisy[~nlos], ranges[~nlos])
    noisy, _ = RangeNoise(dropout=0.1).apply(ranges, rng)
    assert abs(np.isnan(noisy).mean() - 0.1) < 0.01
    assert (RangeNoise(sigma=50.0).apply(ranges, rng)[0] >= 0).all()


def test_noise_is_reproducible_with_a_seed():
    ranges = np.full((5, 4), 10.0)
    noise = RangeNoise(sigma=0.2, nlos_fraction=0.3, nlos_gamma=1.0, dropout=0.1)
    first = noise.apply(ranges, np.random.default_rng(7))[0]
    second = noise.apply(ranges, np.random.default_rng(7))[0]
    np.testing.assert_array_equal(first, second)


def test_working_cycle_is_smooth_and_above_ground():
    model = truck_pump()
    trajectory = working_cycle(model, duration=60.0, rate=10.0, rng=np.random.default_rng(2))
    assert trajectory.joints.shape == (600, 5, 3) and trajectory.times[-1] == pytest.approx(59.9)
    assert trajectory.joints[..., 2].min() > 0.5
    angular_speed = np.abs(np.diff(np.column_stack([trajectory.slew, trajectory.pitches]),
                                   axis=0)) * 10.0
    assert angular_speed.max() < 0.17                                   # rad/s
    np.testing.assert_allclose(model.section_lengths(trajectory.joints),
                               np.broadcast_to(model.arm_lengths, (600, 5)))
