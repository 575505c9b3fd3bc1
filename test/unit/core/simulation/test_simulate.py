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

from epp_ros.core.simulation.simulate import (JoystickMotion, make_motion, random_posture,
                                              RangeNoise, STOP_PROBABILITY, truck_pump,
                                              working_cycle, WorkingMotion, xie3dim)
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


def working_formula(times, p, start, periods, phases):
    """Return the working cycle as its docstring writes it."""
    slew = start + np.radians(60.0) * np.sin(2 * np.pi * times / 40.0)
    rest = np.radians(np.linspace(55.0, -45.0, p))
    pitches = rest + np.radians(10.0) * np.sin(2 * np.pi * times[:, None] / periods + phases)
    return slew, pitches


def test_working_cycle_is_its_documented_formula_and_the_motion_samples_it():
    model = truck_pump()
    rng = np.random.default_rng(4)
    start, periods, phases = (rng.uniform(-np.pi, np.pi), rng.uniform(20.0, 35.0, 5),
                              rng.uniform(0.0, 2 * np.pi, 5))
    trajectory = working_cycle(model, 30.0, 10.0, np.random.default_rng(4))
    times = np.arange(300) / 10.0
    np.testing.assert_array_equal(trajectory.times, times)
    slew, pitches = working_formula(times, 5, start, periods, phases)
    np.testing.assert_allclose(trajectory.slew, slew, rtol=0, atol=1e-15)
    np.testing.assert_allclose(trajectory.pitches, pitches, rtol=0, atol=1e-15)
    np.testing.assert_allclose(trajectory.joints, model.forward_kinematics(slew, pitches),
                               rtol=0, atol=1e-12)
    fixed = working_cycle(model, 5.0, 2.0)
    slew, pitches = working_formula(np.arange(10) / 2.0, 5, 0.0, np.linspace(20, 35, 5),
                                    np.zeros(5))
    np.testing.assert_allclose(fixed.pitches, pitches, rtol=0, atol=1e-15)
    # At any time, not only the samples.
    motion = WorkingMotion(model, np.random.default_rng(4))
    odd = np.array([0.013, 7.77, 123.4])
    slew, pitches = working_formula(odd, 5, start, periods, phases)
    np.testing.assert_allclose(motion.angles(odd)[0], slew, rtol=0, atol=1e-15)
    np.testing.assert_allclose(motion.joints(odd), model.forward_kinematics(slew, pitches),
                               rtol=0, atol=1e-12)
    assert motion.joints(1.5).shape == (5, 3)


def joystick_samples(motion, seconds):
    """Return the angles (T, p + 1) every 10 ms and the rates between samples (T - 1, p + 1)."""
    times = np.arange(int(round(seconds * 100))) * 0.01
    slew, pitches = motion.angles(times)
    angles = np.column_stack([slew, pitches])
    return times, angles, np.diff(angles, axis=0) / 0.01


def test_joystick_rates_are_piecewise_constant_bounded_and_abrupt():
    model = truck_pump()
    motion = JoystickMotion(model, 300.0, np.random.default_rng(5), max_rate=0.3)
    times, angles, rates = joystick_samples(motion, 300.0)
    segment = np.searchsorted(motion.breakpoints, times[:-1], side='right') - 1
    np.testing.assert_allclose(rates, motion.rates[segment], rtol=0, atol=1e-9)
    assert np.abs(motion.rates).max() <= 0.3
    jumps = np.abs(np.diff(rates, axis=0))
    assert (jumps > 0.1).sum() > 100                    # from one 10 ms step to the next
    assert np.abs(rates).max() > 0.25                   # the whole range of rates is used
    # The slew is never steered: its rate changes only when a hold ends (1..6 s).
    changes = times[1:-1][jumps[:, 0] > 1e-6]
    assert np.diff(changes).min() >= 1.0 - 1e-9


def test_joystick_stops_a_third_of_the_time():
    # Holds of exactly 0.5 s: the slew's stopped time counts independent draws.
    motion = JoystickMotion(truck_pump(), 3000.0, np.random.default_rng(6), hold=(0.5, 0.5))
    held = np.diff(motion.breakpoints)
    stopped = held[motion.rates[:, 0] == 0].sum() / held.sum()
    draws = 3000.0 / 0.5
    assert STOP_PROBABILITY == pytest.approx(1 / 3)
    assert abs(stopped - 1 / 3) < 5 * np.sqrt((1 / 3) * (2 / 3) / draws)


def test_joystick_keeps_the_pitch_limits_and_the_joints_above_ground():
    model = truck_pump()
    low, high = np.radians([10.0, -70.0, -70.0, -70.0, -70.0]), np.radians([85.0] + [70.0] * 4)
    for seed in range(3):
        motion = JoystickMotion(model, 200.0, np.random.default_rng(seed))
        times, angles, _ = joystick_samples(motion, 200.0)
        heights = model.forward_kinematics(angles[:, 0], angles[:, 1:])[..., 2]
        assert heights.min() >= 0.5 - 1e-9
        assert heights.min() < 0.6                      # the ground was reached: steering ran
        odd = np.random.default_rng(seed).uniform(0, 200.0, 5000)
        assert motion.joints(odd)[..., 2].min() >= 0.5 - 1e-3
        pitches = motion.angles(odd)[1]
        assert np.all((pitches >= low - 1e-12) & (pitches <= high + 1e-12))
    pinned = motion.angles([-5.0, 0.0, 200.0, 250.0])[1]
    np.testing.assert_array_equal(pinned[0], pinned[1])          # still before the start
    np.testing.assert_array_equal(pinned[2], pinned[3])          # and after the end


def test_joystick_and_motion_arguments_are_checked():
    model, rng = truck_pump(), np.random.default_rng(0)
    with pytest.raises(ValueError, match='duration'):
        JoystickMotion(model, 0.0, rng)
    with pytest.raises(ValueError, match='hold'):
        JoystickMotion(model, 10.0, rng, hold=(3.0, 1.0))
    with pytest.raises(ValueError, match='max_rate'):
        JoystickMotion(model, 10.0, rng, max_rate=-0.1)
    assert isinstance(make_motion('joystick', model, 5.0, rng), JoystickMotion)
    assert isinstance(make_motion('working', model, 5.0, rng), WorkingMotion)
    with pytest.raises(ValueError, match='valid: working, joystick'):
        make_motion('dance', model, 5.0, rng)
