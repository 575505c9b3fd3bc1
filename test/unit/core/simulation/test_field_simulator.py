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

"""The field simulator: each effect does what it says, alone and together."""
from epp_ros.core import BoomModel, PostureEstimator
from epp_ros.core.simulation.simulate import (FIELD_EFFECTS, field_effects, FieldEffects,
                                              FieldSimulator, JoystickMotion, Motion,
                                              simulate_field, truck_pump, WorkingMotion)
import numpy as np
import pytest

#: Standard errors a statistic may be off by before a test calls it wrong.
TOLERANCE_SE = 5.0


class Still(Motion):
    """A boom that stands still."""

    def __init__(self, model, slew=0.3, pitch=np.radians(30.0)):
        self.model, self.slew = model, slew
        self.pitches = np.full(model.n_sections, pitch)

    def angles(self, times):
        times = np.asarray(times, dtype=float)
        return (np.full(times.shape, self.slew),
                np.broadcast_to(self.pitches, times.shape + self.pitches.shape).copy())


def many_anchors(count, sections=5, length=4.0, seed=0):
    """Return a boom with ``count`` anchors scattered around the truck: many links."""
    anchors = np.random.default_rng(seed).uniform([-15, -15, 0], [15, 15, 5], (count, 3))
    return BoomModel(np.full(sections, length), [0.0, 0.0, 3.5], anchors)


def run(model, effects, frames, motion=None, seed=1, frame_period=0.1):
    simulator = FieldSimulator(model, effects, np.random.default_rng(seed), frame_period)
    motion = Still(model) if motion is None else motion
    return simulator, [simulator.frame(motion, index * frame_period)
                       for index in range(frames)]


def true_ranges(simulator, frame):
    return np.linalg.norm(frame.joints[:, None] - simulator.true_anchors[None], axis=-1)


def stack(frames, name):
    return np.array([getattr(frame, name) for frame in frames])


def chain_statistics(states):
    """Return the fraction of time bad and the mean bad run in frames, of (T, ...) states."""
    states = states.reshape(len(states), -1)
    entries = (states[1:] & ~states[:-1]).sum() + states[0].sum()
    return states.mean(), states.sum() / entries


def markov_run_frames(fraction, duration, frame_period):
    """Return the mean bad run in frames of the sampled chain: 1 / P(bad -> good)."""
    memory = duration * (1 - fraction)
    decay = np.exp(-frame_period / memory) if memory > 0 else 0.0
    return 1.0 / ((1 - fraction) * (1 - decay))


def markov_fraction_se(fraction, duration, seconds, chains):
    """Return the standard error of the time-averaged fraction of independent chains."""
    memory = duration * (1 - fraction)
    return np.sqrt(2 * fraction * (1 - fraction) * memory / seconds / chains)


def test_range_sigma_grows_with_distance_as_asked():
    model = truck_pump(n_anchors=7)
    sigma0, slope, count = 0.05, 0.02, 2000
    simulator, frames = run(model, FieldEffects(sigma=sigma0, sigma_per_metre=slope), count)
    distances = true_ranges(simulator, frames[0]).ravel()
    errors = (stack(frames, 'ranges') - true_ranges(simulator, frames[0])).reshape(count, -1)
    spread = errors.std(axis=0, ddof=1)
    se = spread / np.sqrt(2 * (count - 1))
    assert np.ptp(distances) > 10.0                     # the slope is measurable
    assert np.all(np.abs(errors.mean(axis=0)) < TOLERANCE_SE * spread / np.sqrt(count))
    assert np.all(np.abs(spread - (sigma0 + slope * distances)) < TOLERANCE_SE * se)
    # Weighted regression of the spread on the distance.
    design = np.column_stack([np.ones_like(distances), distances]) / se[:, None]
    fit, *_ = np.linalg.lstsq(design, spread / se, rcond=None)
    covariance = np.linalg.inv(design.T @ design)
    assert abs(fit[0] - sigma0) < TOLERANCE_SE * np.sqrt(covariance[0, 0])
    assert abs(fit[1] - slope) < TOLERANCE_SE * np.sqrt(covariance[1, 1])


def test_offsets_are_constant_per_device_and_add_up():
    model = truck_pump()
    effects = FieldEffects(sigma=0.0, tag_offset=0.1, anchor_offset=0.1)
    simulator, frames = run(model, effects, 30, WorkingMotion(model, np.random.default_rng(2)))
    expected = simulator.tag_offsets[:, None] + simulator.anchor_offsets[None, :]
    for frame in frames:
        np.testing.assert_allclose(frame.ranges - true_ranges(simulator, frame), expected,
                                   atol=1e-9)
    draws = [FieldSimulator(model, effects, np.random.default_rng(seed))
             for seed in range(400)]
    for offsets in (np.ravel([s.tag_offsets for s in draws]),
                    np.ravel([s.anchor_offsets for s in draws])):
        assert abs(offsets.std() - 0.1) < TOLERANCE_SE * 0.1 / np.sqrt(2 * offsets.size)
        assert abs(offsets.mean()) < TOLERANCE_SE * 0.1 / np.sqrt(offsets.size)
    assert not FieldSimulator(model).tag_offsets.any()                # off by default


def test_moved_anchors_are_ranged_to_and_only_the_moving_ones_move():
    model = truck_pump()
    simulator, frames = run(model, FieldEffects(sigma=0.0, anchor_shift=0.2), 3)
    assert model.base_anchor() == 0 and simulator.moving_anchors == (1, 2, 3, 4, 5)
    np.testing.assert_array_equal(simulator.true_anchors[0], model.anchors[0])
    assert np.all(np.linalg.norm(simulator.true_anchors[1:] - model.anchors[1:], axis=1) > 0)
    for frame in frames:
        np.testing.assert_allclose(frame.ranges, true_ranges(simulator, frame), atol=1e-12)
        assert not np.allclose(frame.ranges[:, 1:], model.ranges(frame.joints)[:, 1:],
                               atol=1e-3)
    only = FieldSimulator(model, FieldEffects(anchor_shift=0.2, moving_anchors=(2,)))
    moved = np.linalg.norm(only.true_anchors - model.anchors, axis=1) > 0
    np.testing.assert_array_equal(moved, np.arange(6) == 2)
    shifts = np.ravel([FieldSimulator(model, FieldEffects(anchor_shift=0.2),
                                      np.random.default_rng(seed)).true_anchors[1:]
                       - model.anchors[1:] for seed in range(300)])
    assert abs(shifts.std() - 0.2) < TOLERANCE_SE * 0.2 / np.sqrt(2 * shifts.size)
    with pytest.raises(ValueError, match='moving_anchors'):
        FieldSimulator(model, FieldEffects(anchor_shift=0.2, moving_anchors=(6,)))


def test_persistent_nlos_has_the_asked_fraction_duration_and_excess():
    model = many_anchors(60)
    fraction, duration, gamma, count, period = 0.2, 3.0, 1.0, 3000, 0.1
    effects = FieldEffects(sigma=0.0, nlos_fraction=fraction, nlos_duration=duration,
                           nlos_gamma=gamma)
    simulator, frames = run(model, effects, count, frame_period=period)
    blocked = stack(frames, 'nlos')
    links = blocked[0].size
    seen_fraction, seen_run = chain_statistics(blocked)
    assert abs(seen_fraction - fraction) < TOLERANCE_SE * markov_fraction_se(
        fraction, duration, count * period, links)
    expected_run = markov_run_frames(fraction, duration, period)
    entries = blocked.sum() / seen_run
    assert abs(seen_run - expected_run) < TOLERANCE_SE * expected_run / np.sqrt(entries)
    assert abs(expected_run * period - duration) < period          # the continuous mean
    # The excess: exponential with mean gamma on blocked links, drawn anew each frame.
    excess = stack(frames, 'ranges') - true_ranges(simulator, frames[0])
    np.testing.assert_array_equal(excess[~blocked], 0.0)
    assert excess[blocked].min() > 0
    assert abs(excess[blocked].mean() - gamma) < TOLERANCE_SE * gamma / np.sqrt(blocked.sum())
    both = blocked[1:] & blocked[:-1]
    assert abs(np.corrcoef(excess[1:][both], excess[:-1][both])[0, 1]) < \
        TOLERANCE_SE / np.sqrt(both.sum())
    # The chains start in their stationary distribution.
    first = np.ravel([FieldSimulator(model, effects, np.random.default_rng(seed))
                      .frame(Still(model), 0.0).nlos for seed in range(40)])
    assert abs(first.mean() - fraction) < TOLERANCE_SE * np.sqrt(
        fraction * (1 - fraction) / first.size)


def test_nlos_without_duration_is_drawn_anew_each_frame():
    model = many_anchors(60)
    _, frames = run(model, FieldEffects(nlos_fraction=0.2, nlos_duration=0.0), 500)
    blocked = stack(frames, 'nlos')
    _, seen_run = chain_statistics(blocked)
    entries = blocked.sum() / seen_run
    assert abs(seen_run - 1.25) < TOLERANCE_SE * 1.25 / np.sqrt(entries)   # 1 / (1 - f)


def test_dropouts_silence_whole_rows_with_the_asked_fraction_and_duration():
    sections, fraction, duration, count, period = 50, 0.1, 3.0, 5000, 0.3
    model = BoomModel(np.full(sections, 0.4), [0.0, 0.0, 3.5],
                      [[0, 0, 3.5], [5, 4, 0.4], [5, -4, 0.4], [-5, 0, 2.0]])
    effects = FieldEffects(dropout_fraction=fraction, dropout_duration=duration)
    _, frames = run(model, effects, count, frame_period=period)
    ranges, silent = stack(frames, 'ranges'), stack(frames, 'silent')
    np.testing.assert_array_equal(np.isnan(ranges), np.repeat(silent[..., None], 4, axis=2))
    seen_fraction, seen_run = chain_statistics(silent)
    assert abs(seen_fraction - fraction) < TOLERANCE_SE * markov_fraction_se(
        fraction, duration, count * period, sections)
    expected_run = markov_run_frames(fraction, duration, period)
    entries = silent.sum() / seen_run
    assert abs(seen_run - expected_run) < TOLERANCE_SE * expected_run / np.sqrt(entries)


def test_link_dropouts_are_independent_single_ranges():
    model = many_anchors(40)
    _, frames = run(model, FieldEffects(link_dropout=0.3), 400)
    missing = np.isnan(stack(frames, 'ranges'))
    assert abs(missing.mean() - 0.3) < TOLERANCE_SE * np.sqrt(0.21 / missing.size)
    again = missing[1:][missing[:-1]].mean()                    # no memory
    assert abs(again - 0.3) < TOLERANCE_SE * np.sqrt(0.21 / missing[:-1].sum())
    assert not missing.all(axis=2).any()                        # no whole rows


def test_tdma_ranges_each_tag_at_its_slot_time():
    model = truck_pump()
    motion = JoystickMotion(model, 10.0, np.random.default_rng(3))
    simulator = FieldSimulator(model, FieldEffects(sigma=0.0, tdma=True), frame_period=0.1)
    for stamp in (1.0, 1.1, 1.2):
        frame = simulator.frame(motion, stamp)
        np.testing.assert_allclose(frame.range_stamps,
                                   stamp - 0.1 + np.arange(1, 6) * 0.02, rtol=0, atol=1e-12)
        assert frame.range_stamps[-1] == stamp
        for tag, slot in enumerate(frame.range_stamps):
            np.testing.assert_allclose(frame.ranges[tag],
                                       model.ranges(motion.joints(slot))[tag], rtol=1e-12)
        np.testing.assert_allclose(frame.joints, motion.joints(stamp), rtol=1e-12)
        assert not np.allclose(frame.ranges[:-1], model.ranges(frame.joints)[:-1], atol=1e-3)
    plain = FieldSimulator(model, FieldEffects(sigma=0.0), frame_period=0.1)
    frame = plain.frame(motion, 1.0)
    np.testing.assert_array_equal(frame.range_stamps, np.full(5, 1.0))
    np.testing.assert_allclose(frame.ranges, model.ranges(frame.joints), rtol=1e-12)


def test_inclinometer_bias_varies_slowly_with_the_asked_spread():
    model, bias, period = truck_pump(), np.radians(2.0), 120.0
    effects = FieldEffects(inclinometers=True, pitch_sigma=0.0, inclinometer_bias=bias,
                           bias_period=period)
    simulator, frames = run(model, effects, 1200, WorkingMotion(model), frame_period=0.1)
    errors = stack(frames, 'pitches') - stack(frames, 'pitches_true')
    np.testing.assert_allclose(errors, [simulator.inclinometer_bias(f.stamp) for f in frames],
                               atol=1e-12)
    # Slow: per frame it changes by at most 2 pi a T / period, yet it does change.
    fastest = np.abs(simulator.bias_amplitude) * 2 * np.pi * 0.1 / period
    assert np.all(np.abs(np.diff(errors, axis=0)) <= fastest + 1e-12)
    assert np.all(np.ptp(errors, axis=0) > 0.5 * np.abs(simulator.bias_amplitude))
    # At a random time, over runs and sections, its standard deviation is the asked one.
    rng = np.random.default_rng(4)
    samples = np.ravel([FieldSimulator(model, effects, np.random.default_rng(seed))
                        .inclinometer_bias(rng.uniform(0, 1000)) for seed in range(600)])
    spread = samples.std()
    se = np.std(samples ** 2) / (2 * spread * np.sqrt(samples.size))
    assert abs(spread - bias) < TOLERANCE_SE * se


def test_angle_sensor_noise_and_inputs():
    model = truck_pump()
    effects = FieldEffects(inclinometers=True, slew_encoder=True)
    _, frames = run(model, effects, 2000)
    pitch_errors = (stack(frames, 'pitches') - stack(frames, 'pitches_true')).ravel()
    sigma = effects.pitch_sigma
    assert abs(pitch_errors.std() - sigma) < TOLERANCE_SE * sigma / np.sqrt(2 * 10000)
    slew_errors = stack(frames, 'slew') - stack(frames, 'slew_true')
    assert np.abs(slew_errors).max() <= effects.slew_error
    uniform_sigma = effects.slew_error / np.sqrt(3.0)
    assert abs(slew_errors.std() - uniform_sigma) < \
        TOLERANCE_SE * uniform_sigma * np.sqrt(0.8 / 4 / 2000)        # kurtosis of uniform
    inputs = frames[-1].inputs()
    assert set(inputs) == {'ranges', 'stamp', 'range_stamps', 'pitches', 'slew'}
    _, plain = run(model, FieldEffects(), 1)
    assert set(plain[0].inputs()) == {'ranges', 'stamp', 'range_stamps'}
    assert plain[0].pitches is None and plain[0].slew is None
    estimator = PostureEstimator(model, 'chain')
    joints = estimator.update(**frames[-1].inputs())
    assert joints.shape == (5, 3)


@pytest.mark.parametrize('field, value', [
    ('sigma', -0.1), ('sigma', float('nan')), ('sigma_per_metre', float('inf')),
    ('tag_offset', -1.0), ('anchor_offset', 'x'), ('anchor_shift', -0.2),
    ('nlos_fraction', 1.5), ('nlos_duration', -1.0), ('nlos_gamma', -1.0),
    ('dropout_fraction', -0.1), ('dropout_duration', float('nan')), ('link_dropout', 2.0),
    ('pitch_sigma', -1.0), ('inclinometer_bias', -1.0), ('bias_period', 0.0),
    ('slew_error', float('inf')), ('tdma', 'yes'), ('inclinometers', 1),
    ('slew_encoder', None), ('moving_anchors', (-1,)), ('moving_anchors', (1, 1)),
    ('moving_anchors', (1.5,)), ('moving_anchors', 3),
])
def test_field_effects_refuse_bad_values_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f'FieldEffects.{field} '):
        FieldEffects(**{field: value})


def test_field_effects_defaults_are_off_and_frozen():
    effects = FieldEffects(moving_anchors=[2, 3])
    assert effects.moving_anchors == (2, 3)
    with pytest.raises(AttributeError):
        effects.sigma = 1.0
    model = truck_pump()
    simulator, frames = run(model, FieldEffects(sigma=0.0), 5)
    for frame in frames:
        np.testing.assert_allclose(frame.ranges, model.ranges(frame.joints), rtol=1e-12)
        assert not frame.nlos.any() and not frame.silent.any()


def test_presets_and_their_combinations():
    default = FieldEffects()
    assert set(FIELD_EFFECTS) == {'sigma_high', 'sigma_low', 'sigma_distance',
                                  'nlos_persistent', 'tdma', 'dropouts', 'offsets',
                                  'anchors_moved', 'inclinometer_bias', 'real_uwb'}
    assert all(preset != default for preset in FIELD_EFFECTS.values())
    combined = field_effects('nlos_persistent, tdma,offsets')
    assert (combined.nlos_fraction, combined.nlos_duration, combined.nlos_gamma) == \
        (0.2, 3.0, 1.0)
    assert combined.tdma and combined.tag_offset == combined.anchor_offset == 0.1
    assert combined.sigma == default.sigma and combined.dropout_fraction == 0.0
    assert field_effects(['sigma_high', 'sigma_low']).sigma == 0.3        # first one wins
    assert field_effects(['sigma_low', 'sigma_high']).sigma == 0.01
    distance = field_effects('sigma_distance')
    assert (distance.sigma, distance.sigma_per_metre) == (0.03, 0.01)
    bias = field_effects('inclinometer_bias')
    assert bias.inclinometers and bias.inclinometer_bias == pytest.approx(np.radians(2.0))
    assert field_effects('dropouts').dropout_fraction == 0.1
    assert field_effects('anchors_moved').anchor_shift == 0.2
    for names in ('sigma_high,fog', ['nope'], '', []):
        with pytest.raises(ValueError, match='valid: sigma_high, sigma_low'):
            field_effects(names)


def test_simulate_field_stamps_and_reproducibility():
    model = truck_pump()
    motion = WorkingMotion(model, np.random.default_rng(5))
    effects = field_effects('nlos_persistent,dropouts,offsets,sigma_distance')
    frames = simulate_field(model, motion, 1.0, effects, np.random.default_rng(6))
    np.testing.assert_allclose([f.stamp for f in frames], np.arange(10) * 0.1)
    again = simulate_field(model, motion, 1.0, effects, np.random.default_rng(6))
    for first, second in zip(frames, again):
        np.testing.assert_array_equal(first.ranges, second.ranges)
    assert len(simulate_field(model, motion, 2.0, frame_period=0.25)) == 8
    simulator = FieldSimulator(model)
    simulator.frame(motion, 1.0)
    with pytest.raises(ValueError, match='increase'):
        simulator.frame(motion, 1.0)
    with pytest.raises(ValueError, match='frame_period'):
        FieldSimulator(model, frame_period=0.0)


def test_anchor_ranges_measure_true_distances_plus_both_offsets():
    model = truck_pump()
    effects = FieldEffects(sigma=0.05, sigma_per_metre=0.002, anchor_offset=0.2,
                           anchor_shift=0.3)
    simulator = FieldSimulator(model, effects, np.random.default_rng(3))
    rounds = np.array([simulator.anchor_ranges() for _ in range(2000)])
    m = model.n_anchors
    assert rounds.shape == (2000, m, m)
    assert np.isnan(rounds[:, np.arange(m), np.arange(m)]).all()
    anchors = simulator.true_anchors
    distances = np.linalg.norm(anchors[:, None] - anchors[None], axis=-1)
    offsets = simulator.anchor_offsets[:, None] + simulator.anchor_offsets
    sigma = effects.sigma + effects.sigma_per_metre * distances
    off = ~np.eye(m, dtype=bool)
    errors = rounds - distances - offsets
    np.testing.assert_array_less(np.abs(errors.mean(0))[off],
                                 TOLERANCE_SE * sigma[off] / np.sqrt(len(rounds)))
    np.testing.assert_allclose(errors.std(0)[off], sigma[off], rtol=0.1)
    # Each direction is its own measurement: i -> j and j -> i are uncorrelated.
    upper = np.triu_indices(m, 1)
    forth, back = errors[:, upper[0], upper[1]], errors[:, upper[1], upper[0]]
    correlation = ((forth * back).mean(0) / (forth.std(0) * back.std(0)))
    assert np.abs(correlation).max() < TOLERANCE_SE / np.sqrt(len(rounds))


def test_anchor_ranges_leave_the_frames_draws_alone():
    model = truck_pump()
    effects = field_effects('offsets,anchors_moved,nlos_persistent')
    plain, frames = run(model, effects, 20, seed=4)
    asking = FieldSimulator(model, effects, np.random.default_rng(4))
    np.testing.assert_array_equal(asking.true_anchors, plain.true_anchors)
    for index, frame in enumerate(frames):
        asking.anchor_ranges()
        np.testing.assert_array_equal(asking.frame(Still(model), index * 0.1).ranges,
                                      frame.ranges)
    # The own stream is reproducible; a given generator is used instead.
    first = FieldSimulator(model, effects, np.random.default_rng(4)).anchor_ranges()
    again = FieldSimulator(model, effects, np.random.default_rng(4)).anchor_ranges()
    np.testing.assert_array_equal(first, again)
    given = plain.anchor_ranges(np.random.default_rng(9))
    np.testing.assert_array_equal(given, plain.anchor_ranges(np.random.default_rng(9)))
    assert not np.array_equal(given, first, equal_nan=True)


def link_errors_of(simulator, frames):
    """Return measured - true ranges (T, p, m), with the device offsets taken out."""
    errors = np.array([frame.ranges - true_ranges(simulator, frame) for frame in frames])
    return errors - simulator.tag_offsets[:, None] - simulator.anchor_offsets


def test_links_have_biases_of_their_own_beside_the_devices():
    model = many_anchors(12)
    effects = FieldEffects(sigma=0.02, range_bias=0.18, link_offset=0.045, tag_offset=0.05,
                           anchor_offset=0.05)
    simulator, frames = run(model, effects, 400)
    errors = link_errors_of(simulator, frames)
    means = errors.mean(axis=0)                                 # each link's bias
    links = means.size
    # The frames' noise averages to 0.02 / sqrt(400) = 1 mm per link.
    np.testing.assert_allclose(means, 0.18 + simulator.links.link_offsets,
                               atol=TOLERANCE_SE * 0.02 / np.sqrt(400))
    pair = simulator.links.link_offsets
    # The pair term is not a tag plus an anchor term: of a fit of both, it stays.
    rows = means - means.mean(axis=1, keepdims=True)
    residual = rows - rows.mean(axis=0, keepdims=True)
    dof = (model.n_sections - 1) * (model.n_anchors - 1)
    expected = 0.045 ** 2 * dof / links
    assert np.mean(residual ** 2) == pytest.approx(expected, rel=TOLERANCE_SE * np.sqrt(2 / dof))
    assert np.std(pair) == pytest.approx(0.045, rel=TOLERANCE_SE / np.sqrt(2 * links))


def test_link_bias_follows_the_range_curve():
    model = many_anchors(30)
    curve = ((2.0, -0.01), (6.0, -0.01), (25.0, 0.23), (55.0, 0.30))
    simulator, frames = run(model, FieldEffects(sigma=0.02, bias_curve=curve), 50)
    errors = link_errors_of(simulator, frames).mean(axis=0)
    distances = true_ranges(simulator, frames[0])
    knots = np.array(curve)
    np.testing.assert_allclose(errors, np.interp(distances, knots[:, 0], knots[:, 1]),
                               atol=TOLERANCE_SE * 0.02 / np.sqrt(50))
    assert FieldEffects(bias_curve=[[1, 0.1], [5, 0.2]]).bias_curve == ((1.0, 0.1), (5.0, 0.2))
    for bad in ([[5, 0.1], [1, 0.2]], [[1, np.nan]], 'abc', [[-1, 0.0]]):
        with pytest.raises(ValueError, match='bias_curve'):
            FieldEffects(bias_curve=bad)


def test_link_bias_changes_with_the_sections_pitch():
    model = many_anchors(8)
    effects = FieldEffects(sigma=0.0, orientation_bias=0.06)
    low = FieldSimulator(model, effects, np.random.default_rng(3))
    high = FieldSimulator(model, effects, np.random.default_rng(3))
    level = Still(model, pitch=np.radians(10.0))
    lifted = Still(model, pitch=np.radians(60.0))
    # The same links (same seed), the tags turned: their biases change, not their scale.
    turned = (high.frame(lifted, 0.0).ranges - true_ranges(high, high.frame(lifted, 0.1))
              - (low.frame(level, 0.0).ranges - true_ranges(low, low.frame(level, 0.1))))
    assert np.sqrt(np.mean(turned ** 2)) > 0.02
    biases = [link_errors_of(simulator, [simulator.frame(Still(model, pitch=pitch), 0.0)])
              for pitch in np.radians(np.linspace(-80, 80, 40))
              for simulator in [FieldSimulator(model, effects, np.random.default_rng(3))]]
    # Over the tag's orientations a link's bias has RMS 0.06 (the a, b of 40 links).
    links = model.n_sections * model.n_anchors
    assert np.sqrt(np.mean(np.square(biases))) == pytest.approx(
        0.06, rel=TOLERANCE_SE / np.sqrt(2 * links))


def test_noise_is_correlated_in_time_as_asked():
    model = many_anchors(10)
    effects = FieldEffects(sigma=0.07, correlated_fraction=0.76, noise_correlation_time=2.4)
    simulator, frames = run(model, effects, 3000)
    errors = link_errors_of(simulator, frames).reshape(3000, -1)
    errors = errors - errors.mean(axis=0)
    assert errors.std() == pytest.approx(0.07, rel=0.05)
    for lag in (1, 10):
        measured = np.mean(errors[lag:] * errors[:-lag]) / np.mean(errors ** 2)
        expected = 0.76 * np.exp(-lag * 0.1 / 2.4)
        # 50 links x 3000 frames, about 3000 / 48 independent stretches each.
        standard_error = 1.0 / np.sqrt(errors.shape[1] * 3000 / (2 * 24))
        assert measured == pytest.approx(expected, abs=TOLERANCE_SE * standard_error)


def test_outliers_last_a_few_frames_at_the_asked_rate():
    model = many_anchors(20)
    effects = FieldEffects(sigma=0.01, outlier_rate=0.2, outlier_duration=0.25,
                           outlier_size=1.0)
    simulator, frames = run(model, effects, 2000)
    errors = link_errors_of(simulator, frames)
    outlying = np.abs(errors) > 0.1          # 10 sigma: no clean range is taken for one
    fraction, run_frames = chain_statistics(outlying)
    expected_fraction = 0.2 * 0.25
    assert fraction == pytest.approx(expected_fraction, abs=TOLERANCE_SE * markov_fraction_se(
        expected_fraction, 0.25, 200.0, outlying[0].size) + 0.01)
    # Sampled at 10 Hz an outlier lasts 1 / P(end) frames; 8 % of excesses are < 0.1 m.
    assert run_frames == pytest.approx(markov_run_frames(expected_fraction, 0.25, 0.1),
                                       rel=0.25)
    # RMS of N(0, 1) beyond 0.1: 1.0 (the few under 0.1 are left out), 5 % from 1,200.
    assert np.sqrt(np.mean(errors[outlying] ** 2)) == pytest.approx(1.0, rel=0.1)


def test_real_uwb_preset_and_old_runs_unchanged():
    effects = field_effects('real_uwb')
    assert (effects.range_bias, effects.link_offset, effects.correlated_fraction) == \
        (0.18, 0.045, 0.76)
    model = truck_pump()
    # Without the real-link effects every draw of a run is what it was: figures of this
    # run from cb73d97, before they existed (to round-off; a draw more moves them by cm).
    plain = simulate_field(model, WorkingMotion(model, np.random.default_rng(0)), 3.0,
                           field_effects('offsets,nlos_persistent,tdma,dropouts'),
                           np.random.default_rng(1))
    ranges = np.array([frame.ranges for frame in plain])
    assert np.nansum(ranges) == pytest.approx(19090.275053769255, rel=1e-12)
    assert (ranges[5, 2, 3], ranges[17, 4, 1]) == pytest.approx(
        (23.596040505038015, 29.488932211668786), rel=1e-12)
    real = simulate_field(model, WorkingMotion(model, np.random.default_rng(0)), 30.0,
                          effects, np.random.default_rng(1))
    simulator = FieldSimulator(model, effects, np.random.default_rng(1))
    errors = np.array([frame.ranges - np.linalg.norm(
        frame.joints[:, None] - simulator.true_anchors[None], axis=-1) for frame in real])
    assert 0.05 < np.median(errors) < 0.6       # biased, as real links are
