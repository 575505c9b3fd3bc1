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

from epp_ros.app.angles import AngleSamples
import numpy as np
import pytest

NAMES = ['pitch1', 'pitch2', 'pitch3']


def test_a_frame_takes_the_newest_sample_within_the_age_limit():
    samples = AngleSamples('slew', NAMES, max_age=0.2)
    assert samples.at(10.0) == (None, None)                 # nothing yet, nothing counted
    samples.add(10.0, ['slew', 'pitch1', 'pitch2', 'pitch3'], [0.5, 0.9, 0.4, -0.2])
    samples.add(10.05, ['pitch3', 'slew', 'pitch1'], [-0.25, 0.52, 0.95])
    slew, pitches = samples.at(10.1)
    assert slew == 0.52
    np.testing.assert_array_equal(pitches[[0, 2]], [0.95, -0.25])
    assert np.isnan(pitches[1])                              # not in the newest message
    assert samples.at(10.3) == (None, None)                  # 0.25 s old
    assert samples.at(9.9)[0] == 0.52                        # 0.15 s ahead still fits
    assert samples.counts == {'messages': 2, 'frames_with_angles': 2,
                              'frames_without_fresh_angles': 1}


def test_bad_messages_are_counted_and_ignored():
    samples = AngleSamples('slew', NAMES, max_age=0.2)
    samples.add(5.0, ['slew', 'pitch1'], [0.1, 0.2])
    samples.add(5.1, ['slew', 'pitch1'], [0.3])                           # malformed
    samples.add(4.9, ['slew'], [0.7])                                     # older
    samples.add(5.2, ['slew', 'boom_temp', 'pitch2'], [np.nan, 3.0, 0.4])
    slew, pitches = samples.at(5.2)
    assert slew is None                                      # NaN is not a measurement
    assert np.isnan(pitches[0]) and pitches[1] == 0.4
    assert samples.counts['malformed'] == 1 and samples.counts['out_of_order'] == 1
    assert samples.counts['unknown_names'] == 1 and samples.counts['messages'] == 4


@pytest.mark.parametrize('slew_name, pitch_names, max_age, message', [
    ('slew', ['a', ''], 0.2, 'must not be empty'),
    ('a', ['a', 'b'], 0.2, 'must differ'),
    ('slew', ['a', 'b'], 0.0, 'angle_max_age'),
])
def test_bad_settings_raise(slew_name, pitch_names, max_age, message):
    with pytest.raises(ValueError, match=message):
        AngleSamples(slew_name, pitch_names, max_age)
