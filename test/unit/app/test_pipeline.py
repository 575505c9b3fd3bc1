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

"""The frame steps node and bag tools share: what is published, and every other frame counted."""
from epp_ros.app.config import load_pump_config
from epp_ros.app.contract import FRAME_NUMBER, frame_number, FrameNumbers
from epp_ros.app.pipeline import RangePipeline
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation.methods import angles_from_joints
from epp_ros.core.simulation.simulate import random_posture
import numpy as np

CONFIG = load_pump_config()
MODEL = CONFIG.model()


def message_of(ranges):
    """Return the name and position of a ``uwb/ranges`` message of tag-anchor ranges (p, m)."""
    return list(CONFIG.link_names), list(np.asarray(ranges, dtype=float).ravel())


def test_good_frames_are_published_and_the_rest_counted_by_reason():
    rng = np.random.default_rng(1)
    joints = random_posture(MODEL, rng)[2]
    names, exact = message_of(MODEL.ranges(joints))
    pipeline = RangePipeline(CONFIG, PostureEstimator(MODEL, 'chain'))
    published = pipeline.step(10.0, names, exact)
    np.testing.assert_allclose(published.joints, joints, atol=1e-5)
    assert published.diagnostics['valid']
    # A repeat, an unset stamp and a message whose fields do not match never reach it.
    for stamp, values in ((10.0, exact), (0.0, exact), (10.1, exact[:-1])):
        step = pipeline.step(stamp, names, values)
        assert step.joints is None and step.diagnostics is None
    # A frame no posture explains reaches it and is refused, by its status.
    absurd = pipeline.step(10.2, names, list(rng.uniform(0.5, 300.0, len(exact))))
    assert absurd.joints is None and not absurd.diagnostics['valid']
    assert pipeline.rejected() == {absurd.diagnostics['status']: 1}
    # A stamp 5 s back is a clock jump: the estimator starts over and solves it.
    assert pipeline.step(5.0, names, exact).joints is not None
    counts = pipeline.counts
    assert counts['received'] == 6 and counts['published'] == 2
    assert counts['out_of_order'] == 1 and counts['malformed'] == 2
    assert counts['unsolved'] == 1 and counts['clock_jumps'] == 1
    assert counts['received'] == (counts['published'] + counts['unsolved']
                                  + counts['out_of_order'] + counts['malformed'])


def test_the_ranges_ages_reach_the_estimator():
    joints = random_posture(MODEL, np.random.default_rng(2))[2]
    names, exact = message_of(MODEL.ranges(joints))
    ages = [0.05] * len(exact)
    for method, listed in (('chain', True), ('track', False)):   # track uses them
        pipeline = RangePipeline(CONFIG, PostureEstimator(MODEL, method))
        ignored = pipeline.step(20.0, names, exact, ages).diagnostics['ignored_inputs']
        assert ('range_stamps' in ignored) == listed, method
        # Without ages (an empty effort) every range is at the stamp: nothing to ignore.
        assert 'range_stamps' not in pipeline.step(20.1, names, exact).diagnostics[
            'ignored_inputs']


def numbered(ranges, number):
    """Return a message's name, position and effort with the driver's frame number last."""
    names, values = message_of(ranges)
    return ([*names, FRAME_NUMBER], [*values, float(number)],
            [0.0] * len(values) + [0.0])


def test_frames_the_driver_numbered_but_never_came_are_counted():
    joints = random_posture(MODEL, np.random.default_rng(3))[2]
    pipeline = RangePipeline(CONFIG, PostureEstimator(MODEL, 'chain'))
    # Heard from frame 4 on (1-3 went out before it listened); 6, 7 and 10 lost; then the
    # driver restarts and 1 is lost; an unnumbered message (an older bag) counts nothing.
    for stamp, number in enumerate([4, 5, 8, 9, 11, 2, 3, None], start=1):
        if number is None:
            names, values = message_of(MODEL.ranges(joints))
            ages = ()
        else:
            names, values, ages = numbered(MODEL.ranges(joints), number)
        step = pipeline.step(float(stamp), names, values, ages)
        assert step.joints is not None               # the number is not a link
        np.testing.assert_allclose(step.joints, joints, atol=1e-5)
    counts = pipeline.counts
    assert counts['lost'] == 3 and counts['before_first'] == 3 + 1
    assert counts['sender_restarts'] == 1 and counts['unknown_links'] == 0
    assert counts['received'] == 8 and counts['published'] == 8


def test_frame_numbers_are_read_only_where_the_contract_puts_them():
    names, values, _ = numbered(MODEL.ranges(random_posture(MODEL, np.random.default_rng(4))[2]),
                                7)
    assert frame_number(names, values) == 7
    for bad in (float('nan'), 0.0, -3.0, 2.5, float('inf')):
        assert frame_number(names, [*values[:-1], bad]) is None
    assert frame_number(names[:-1], values[:-1]) is None          # not numbered
    assert frame_number(names, values[:-1]) is None               # fields that do not match
    assert frame_number([], []) is None
    counted = FrameNumbers()
    for number in (1, 2, None, 5, 5):
        counted.add(number)
    assert (counted.lost, counted.before_first, counted.restarts) == (2, 4, 1)


def test_what_is_published_is_the_boom_at_the_angles_the_frame_was_judged_at():
    """The frame's result carries them; a method not held to the lengths is moved onto them."""
    joints = random_posture(MODEL, np.random.default_rng(5))[2]
    names, exact = message_of(MODEL.ranges(joints))
    for method in ('chain', 'epp2'):
        step = RangePipeline(CONFIG, PostureEstimator(MODEL, method)).step(30.0, names, exact)
        estimate = step.diagnostics['estimate']
        slew, pitches = angles_from_joints(MODEL, estimate)
        assert step.angles[0] == step.diagnostics.angles[0] == slew, method
        np.testing.assert_array_equal(step.angles[1], pitches)
        np.testing.assert_array_equal(step.diagnostics.angles[1], pitches)
        np.testing.assert_array_equal(step.joints, MODEL.forward_kinematics(slew, pitches))
        np.testing.assert_allclose(step.joints, joints, atol=1e-4)
