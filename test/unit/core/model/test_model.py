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

from epp_ros.core import BoomModel
import numpy as np
import pytest

ANCHORS = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]]


def test_forward_kinematics_known_postures():
    model = BoomModel([2.0, 3.0], [1.0, 1.0, 1.0], ANCHORS)
    horizontal = model.forward_kinematics(0.0, [0.0, 0.0])
    np.testing.assert_allclose(horizontal, [[3.0, 1.0, 1.0], [6.0, 1.0, 1.0]], atol=1e-12)
    # Slewed to +y, first section vertical, second horizontal.
    bent = model.forward_kinematics(np.pi / 2, [np.pi / 2, 0.0])
    np.testing.assert_allclose(bent, [[1.0, 1.0, 3.0], [1.0, 4.0, 3.0]], atol=1e-12)


def test_forward_kinematics_batches_and_lengths():
    model = BoomModel([9.0, 7.0, 7.0], [0.0, 0.0, 3.5], ANCHORS)
    rng = np.random.default_rng(0)
    slew = rng.uniform(-np.pi, np.pi, 4)
    pitches = rng.uniform(-1.0, 1.0, (4, 3))
    joints = model.forward_kinematics(slew, pitches)
    assert joints.shape == (4, 3, 3)
    np.testing.assert_allclose(model.section_lengths(joints), np.tile([9.0, 7.0, 7.0], (4, 1)))
    np.testing.assert_allclose(joints[1], model.forward_kinematics(slew[1], pitches[1]))


def test_ranges_are_distances():
    model = BoomModel([1.0], [0.0, 0.0, 0.0], ANCHORS)
    ranges = model.ranges([[3.0, 4.0, 0.0]])
    np.testing.assert_allclose(ranges, [[5.0, np.hypot(7, 4), np.hypot(3, 6), np.sqrt(125)]])


def test_base_anchor_found():
    assert BoomModel([1.0], [0.0, 0.0, 0.0], ANCHORS).base_anchor() == 0
    assert BoomModel([1.0], [0.0, 0.0, 1.0], ANCHORS).base_anchor() is None


@pytest.mark.parametrize('kwargs, field', [
    ({'arm_lengths': []}, 'arm_lengths'),
    ({'arm_lengths': [1.0, -2.0]}, 'arm_lengths'),
    ({'arm_lengths': [1.0, 0.0]}, 'arm_lengths'),
    ({'arm_lengths': [1.0, np.nan]}, 'arm_lengths'),
    ({'arm_lengths': 'long'}, 'arm_lengths'),
    ({'base': [0.0, 0.0]}, 'base'),
    ({'base': [0.0, np.inf, 0.0]}, 'base'),
    ({'anchors': ANCHORS[:2]}, 'anchors'),
    ({'anchors': [[0.0, 0.0]] * 4}, 'anchors'),
    ({'anchors': [[0.0, 0.0, np.nan]] * 4}, 'anchors'),
])
def test_invalid_geometry_names_the_field(kwargs, field):
    args = {'arm_lengths': [1.0, 2.0], 'base': [0.0, 0.0, 0.0], 'anchors': ANCHORS}
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        BoomModel(**args)


def test_model_arrays_are_read_only():
    model = BoomModel([1.0], [0.0, 0.0, 0.0], ANCHORS)
    with pytest.raises(ValueError):
        model.anchors[0, 0] = 5.0


def test_device_offsets_default_to_zero_and_add_to_the_measured_ranges():
    model = BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS)
    assert not model.has_offsets and model.tag_offsets.shape == (2,)
    np.testing.assert_array_equal(model.anchor_offsets, np.zeros(4))
    offset = BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS, anchor_offsets=[0.1, 0.2, 0.3, 0.4],
                       tag_offsets=[-0.05, 0.05])
    joints = offset.forward_kinematics(0.2, [0.5, -0.3])
    np.testing.assert_allclose(offset.ranges(joints), model.ranges(joints))   # true distances
    np.testing.assert_allclose(offset.measured_ranges(joints) - offset.ranges(joints),
                               [[0.05, 0.15, 0.25, 0.35], [0.15, 0.25, 0.35, 0.45]])
    np.testing.assert_allclose(offset.tag_link_offsets(), [[-0.1, 0.0], [0.0, 0.1]])
    assert 'tag_offsets=[-0.05, 0.05]' in repr(offset)
    with pytest.raises(ValueError):
        offset.tag_offsets[0] = 1.0
    calibrated = model.with_calibration(tag_offsets=[0.1, 0.2])
    np.testing.assert_array_equal(calibrated.tag_offsets, [0.1, 0.2])
    np.testing.assert_array_equal(calibrated.anchors, model.anchors)


def test_links_own_offsets_add_to_the_devices_offsets():
    pairs = [[0.01, -0.02, 0.03, 0.0], [0.0, 0.04, -0.01, 0.02]]
    model = BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS, anchor_offsets=[0.1, 0.2, 0.3, 0.4],
                      tag_offsets=[-0.05, 0.05], pair_offsets=pairs)
    joints = model.forward_kinematics(0.2, [0.5, -0.3])
    np.testing.assert_allclose(model.measured_ranges(joints) - model.ranges(joints),
                               np.array([[0.05, 0.15, 0.25, 0.35], [0.15, 0.25, 0.35, 0.45]])
                               + pairs)
    np.testing.assert_allclose(model.tag_link_offsets(), [[-0.1, 0.0], [0.0, 0.1]])  # devices'
    assert model.has_offsets and 'pair_offsets=' in repr(model)
    kept = model.with_calibration(tag_offsets=[0.0, 0.0])
    np.testing.assert_array_equal(kept.pair_offsets, pairs)
    assert BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS, pair_offsets=pairs).has_offsets
    with pytest.raises(ValueError, match='pair_offsets must hold 8 values'):
        BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS, pair_offsets=[0.1] * 6)
    with pytest.raises(ValueError):
        model.pair_offsets[0, 0] = 1.0


@pytest.mark.parametrize('kwargs, message', [
    ({'anchor_offsets': [0.1, 0.2]}, 'anchor_offsets must hold 4 values'),
    ({'tag_offsets': [0.1, 0.2, 0.3]}, 'tag_offsets must hold 2 values'),
    ({'tag_offsets': [0.1, np.nan]}, 'tag_offsets must be finite'),
    ({'anchor_offsets': [0.1, 0.2, 0.3, 25.0]}, 'anchor_offsets must be within'),
    ({'anchor_offsets': 'short'}, 'anchor_offsets must be numeric'),
    ({'tag_offsets': [[0.1, 0.2]]}, 'tag_offsets must be a 1-D array'),
])
def test_invalid_offsets_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        BoomModel([1.0, 2.0], [0.0, 0.0, 0.0], ANCHORS, **kwargs)
