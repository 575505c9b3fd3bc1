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

from epp_ros.app import contract
from epp_ros.app.config import load_pump_config
from epp_ros.uwb.formats.base import RangeRecord
from epp_ros.uwb.frames import FrameAssembler
import numpy as np
import pytest

CONFIG = load_pump_config()
ANCHORS = CONFIG.anchor_ids
TAGS = CONFIG.tag_ids


def full_cycle(assembler, stamp, value=5.0):
    frames = []
    for tag in TAGS:
        for anchor in ANCHORS:
            frames += assembler.add(RangeRecord(anchor, value, tag=tag), stamp)
    return frames


def test_cycle_closes_when_every_pair_reported():
    assembler = FrameAssembler(CONFIG)
    frames = full_cycle(assembler, 100.0)
    assert len(frames) == 1 and assembler.frames == 1
    np.testing.assert_array_equal(frames[0].ranges, np.full((5, 6), 5.0))
    assert frames[0].stamp == 100.0


def test_cycle_closes_after_the_period_with_nan_for_silent_pairs():
    assembler = FrameAssembler(CONFIG, frame_period=0.1)
    assert assembler.add(RangeRecord(ANCHORS[0], 3.0, tag=TAGS[0]), 10.00) == []
    assert assembler.add(RangeRecord(ANCHORS[1], 4.0, tag=TAGS[2]), 10.05) == []
    assert assembler.poll(10.08) == []
    (frame,) = assembler.poll(10.11)
    assert frame.stamp == 10.05
    assert frame.ranges[0, 0] == 3.0 and frame.ranges[2, 1] == 4.0
    assert np.isnan(frame.ranges).sum() == 28
    assert assembler.poll(20.0) == []                  # no ranges, no frame


def test_a_pair_reporting_again_starts_a_new_cycle():
    assembler = FrameAssembler(CONFIG)
    record = RangeRecord(ANCHORS[0], 3.0, tag=TAGS[0])
    assert assembler.add(record, 1.00) == []
    (frame,) = assembler.add(RangeRecord(ANCHORS[0], 3.1, tag=TAGS[0]), 1.01)
    assert frame.ranges[0, 0] == 3.0
    (second,) = assembler.poll(2.0)
    assert second.ranges[0, 0] == 3.1


def test_tag_tag_ranges_ride_along_without_holding_the_cycle_open():
    assembler = FrameAssembler(CONFIG)
    assert assembler.add(RangeRecord(TAGS[2], 7.2, tag=TAGS[1]), 1.0) == []
    assert assembler.add(RangeRecord(TAGS[1], 7.1, tag=TAGS[2]), 1.0) == []
    assert assembler.add(RangeRecord(TAGS[0], 0.0, tag=TAGS[0]), 1.0) == []  # itself
    (frame,) = full_cycle(assembler, 1.01)
    assert frame.tag_ranges[1, 2] == 7.2 and frame.tag_ranges[2, 1] == 7.1
    assert np.isfinite(frame.tag_ranges).sum() == 2
    assert assembler.dropped == {'unknown_anchor': 1}
    # The same tag pair again belongs to the next cycle.
    assembler.add(RangeRecord(TAGS[2], 7.3, tag=TAGS[1]), 2.0)
    (first,) = assembler.add(RangeRecord(TAGS[2], 7.4, tag=TAGS[1]), 2.01)
    (second,) = assembler.poll(3.0)
    assert first.tag_ranges[1, 2] == 7.3 and second.tag_ranges[1, 2] == 7.4
    assert np.isnan(first.ranges).all() and np.isnan(second.ranges).all()


def test_source_tag_applies_when_the_line_names_none():
    assembler = FrameAssembler(CONFIG)
    assembler.add(RangeRecord(ANCHORS[2], 7.5, rx_power_dbm=-81.0), 1.0, source_tag='4')
    (frame,) = assembler.poll(5.0)
    assert frame.ranges[3, 2] == 7.5 and frame.rx_power[3, 2] == -81.0


@pytest.mark.parametrize('record, reason', [
    (RangeRecord(ANCHORS[0], 0.01, tag=TAGS[0]), 'implausible'),
    (RangeRecord(ANCHORS[0], 250.0, tag=TAGS[0]), 'implausible'),
    (RangeRecord(ANCHORS[0], float('nan'), tag=TAGS[0]), 'implausible'),
    (RangeRecord('FFFF', 5.0, tag=TAGS[0]), 'unknown_anchor'),
    (RangeRecord(ANCHORS[0], 5.0, tag='EE'), 'unknown_tag'),
    (RangeRecord(ANCHORS[0], 5.0), 'no_tag'),
    (RangeRecord(ANCHORS[0], 5.0, kind='anchor'), 'anchor_range'),
    (RangeRecord(ANCHORS[0], 5.0, tag=TAGS[0], kind='raw'), 'raw_range'),
])
def test_unused_records_are_counted_by_reason(record, reason):
    assembler = FrameAssembler(CONFIG)
    assert assembler.add(record, 1.0) == []
    assert assembler.dropped == {reason: 1}
    assert assembler.poll(9.0) == []


def test_bad_settings_raise():
    with pytest.raises(ValueError):
        FrameAssembler(CONFIG, frame_period=0.0)
    with pytest.raises(ValueError):
        FrameAssembler(CONFIG, min_range=5.0, max_range=1.0)


def test_whole_tag_lines_close_the_cycle_when_every_tag_reported():
    assembler = FrameAssembler(CONFIG)
    frames = []
    for row, tag in enumerate(TAGS):
        # Each tag misses its last anchor this cycle.
        records = [RangeRecord(anchor, 5.0 + row, tag=tag) for anchor in ANCHORS[:-1]]
        frames += assembler.add_line(records, 1.0 + 0.001 * row, whole=True)
        assert len(frames) == (1 if row == len(TAGS) - 1 else 0)
    np.testing.assert_array_equal(np.isnan(frames[0].ranges[:, -1]), True)
    assert frames[0].ranges[4, 0] == 9.0


def test_a_tag_reporting_twice_starts_the_next_cycle():
    assembler = FrameAssembler(CONFIG)
    line = [RangeRecord(ANCHORS[0], 5.0, tag=TAGS[0])]
    assert assembler.add_line(line, 1.0, whole=True) == []
    (frame,) = assembler.add_line([RangeRecord(ANCHORS[1], 6.0, tag=TAGS[0])], 1.05,
                                  whole=True)
    assert frame.ranges[0, 0] == 5.0 and np.isnan(frame.ranges[0, 1])


def test_lines_that_are_not_whole_wait_for_every_pair_or_the_period():
    assembler = FrameAssembler(CONFIG)
    for tag in TAGS:
        assert assembler.add_line([RangeRecord(ANCHORS[0], 5.0, tag=tag)], 1.0) == []
    assert len(assembler.poll(1.2)) == 1


def test_frames_from_one_read_get_strictly_increasing_stamps():
    assembler = FrameAssembler(CONFIG)
    frames = full_cycle(assembler, 100.0) + full_cycle(assembler, 100.0)
    assert len(frames) == 2 and frames[1].stamp > frames[0].stamp == 100.0


def test_unpadded_ids_as_sketches_print_them_reach_their_pair():
    """pump.yaml says 0B82 and 0001; thotro-style firmware prints B82 and 1."""
    import dataclasses

    from epp_ros.uwb.decoder import LineDecoder
    config = dataclasses.replace(CONFIG, anchor_ids=('0B82',) + ANCHORS[1:],
                                 tag_ids=('0001',) + TAGS[1:])
    assembler = FrameAssembler(config)
    decoder = LineDecoder('auto')
    for line in ['from: B82\t Range: 2.34 m\t RX power: -78.32 dBm',
                 '{"tag":"1","links":[{"A":"0xb82","R":"2.35"}]}']:
        assert decoder.decode(line)
    assembler.add_line(LineDecoder('arduino').decode('from: B82\t Range: 2.34 m'), 1.0,
                       source_tag='1')
    (frame,) = assembler.poll(2.0)
    assert frame.ranges[0, 0] == 2.34 and assembler.dropped == {}


def test_records_that_name_no_anchor_take_the_source_anchor():
    assembler = FrameAssembler(CONFIG)
    record = RangeRecord(None, 3.5)
    assembler.add(record, 1.0, source_tag=TAGS[1], source_anchor=ANCHORS[2])
    assembler.add(record, 1.0, source_tag=TAGS[1])
    (frame,) = assembler.poll(2.0)
    assert frame.ranges[1, 2] == 3.5 and assembler.dropped == {'no_anchor': 1}


def test_each_range_keeps_its_receive_time_and_is_published_with_its_age():
    assembler = FrameAssembler(CONFIG)
    # Tags in their TDMA slots: tag k's line arrives 20 ms after tag k-1's.
    for row, tag in enumerate(TAGS[:-1]):
        records = [RangeRecord(anchor, 5.0, tag=tag) for anchor in ANCHORS]
        assembler.add_line(records, 10.0 + 0.02 * row, whole=True)
    assembler.add(RangeRecord(TAGS[1], 7.2, tag=TAGS[0]), 10.01)            # tag-tag
    (frame,) = assembler.poll(10.2)                                     # the last tag silent
    expected = np.full((5, 6), np.nan)
    expected[:4] = (10.0 + 0.02 * np.arange(4))[:, None]
    np.testing.assert_array_equal(frame.received, expected)
    assert frame.tag_received[0, 1] == 10.01 and np.isfinite(frame.tag_received).sum() == 1
    assert frame.stamp == 10.06
    names, ranges, ages = contract.frame_fields(frame, CONFIG)
    # Numbered in the order closed: the number last, as contract.FRAME_NUMBER.
    assert frame.number == assembler.frames == 1
    assert names[-1] == contract.FRAME_NUMBER and ranges[-1] == 1.0 and ages[-1] == 0.0
    names, ranges, ages = names[:-1], ranges[:-1], ages[:-1]
    assert names == CONFIG.link_names + ['joint1:joint2'] and len(ranges) == len(ages) == 31
    np.testing.assert_allclose(ages[:24], np.repeat([0.06, 0.04, 0.02, 0.0], 6), atol=1e-12)
    assert np.isnan(ages[24:30]).all() and np.isnan(ranges[24:30]).all()
    assert ages[30] == pytest.approx(0.05) and ranges[30] == 7.2
    # The estimators read back each tag's time of measurement.
    links = CONFIG.link_frame(names, ranges, ages)
    np.testing.assert_allclose(links.range_stamps(frame.stamp)[:4], [10.0, 10.02, 10.04, 10.06])
    assert np.isnan(links.ages[4])
    assert contract.ages_of(ages, len(names)).shape == (31,)


def test_a_raised_stamp_keeps_the_receive_times_so_ages_stay_true():
    assembler = FrameAssembler(CONFIG)
    first = full_cycle(assembler, 100.0)
    (second,) = full_cycle(assembler, 100.0)               # the same read: stamp raised 1 us
    assert second.stamp > first[0].stamp and (second.received == 100.0).all()
    _, _, ages = contract.frame_fields(second, CONFIG)
    assert second.number == first[0].number + 1
    np.testing.assert_allclose(ages[:-1], second.stamp - 100.0)       # then the number's
    assert min(ages[:-1]) > 0


def test_anchor_ranges_are_kept_apart_and_labelled_measuring_anchor_first():
    from epp_ros.app import contract
    assembler = FrameAssembler(CONFIG)
    line = [RangeRecord(ANCHORS[1], 5.25, tag=ANCHORS[0], kind='anchor'),
            RangeRecord(ANCHORS[2], 6.5, tag=ANCHORS[0], kind='anchor'),
            RangeRecord(ANCHORS[2], 7.75, tag=ANCHORS[1], kind='anchor')]
    assert assembler.add_line(line, 3.0, whole=True) == []
    assert assembler.poll(9.0) == [] and assembler.frames == 0       # no cycle opened
    anchor_round = assembler.take_anchor_ranges()
    assert assembler.take_anchor_ranges() is None                      # handed over once
    assert anchor_round.stamp == 3.0 and assembler.anchor_ranges == 3 and not assembler.dropped
    names, ranges = contract.anchor_round_fields(anchor_round, CONFIG)
    assert names == ['turret:outrigger_fl', 'turret:outrigger_fr', 'outrigger_fl:outrigger_fr']
    assert ranges == [5.25, 6.5, 7.75]
    matrix, unknown = contract.anchor_range_matrix(CONFIG.anchor_names, names, ranges)
    assert unknown == 0 and matrix.shape == (6, 6) and np.isfinite(matrix).sum() == 3
    assert (matrix[0, 1], matrix[0, 2], matrix[1, 2]) == (5.25, 6.5, 7.75)


def test_anchor_ranges_do_not_disturb_the_cycles():
    assembler = FrameAssembler(CONFIG)
    frames = []
    for tag in TAGS:
        assembler.add(RangeRecord(ANCHORS[3], 4.0, tag=ANCHORS[2], kind='anchor'), 1.0)
        frames += assembler.add_line([RangeRecord(a, 5.0, tag=tag) for a in ANCHORS], 1.0,
                                     whole=True)
    assert len(frames) == 1 and np.isfinite(frames[0].ranges).all()
    assert len(assembler.take_anchor_ranges().ranges) == len(TAGS)


@pytest.mark.parametrize('record, reason', [
    (RangeRecord('FFFF', 5.0, tag=ANCHORS[0], kind='anchor'), 'unknown_anchor'),
    (RangeRecord(ANCHORS[1], 5.0, tag='FFFF', kind='anchor'), 'unknown_anchor'),
    (RangeRecord(ANCHORS[1], 0.01, tag=ANCHORS[0], kind='anchor'), 'implausible'),
    (RangeRecord(ANCHORS[1], 250.0, tag=ANCHORS[0], kind='anchor'), 'implausible'),
    (RangeRecord(ANCHORS[1], 5.0, tag=ANCHORS[1], kind='anchor'), 'implausible'),
    (RangeRecord(None, 5.0, tag=ANCHORS[1], kind='anchor'), 'anchor_range'),
])
def test_unusable_anchor_ranges_are_dropped_and_counted(record, reason):
    assembler = FrameAssembler(CONFIG)
    assert assembler.add(record, 1.0) == []
    assert assembler.dropped == {reason: 1} and assembler.anchor_ranges == 0
    assert assembler.take_anchor_ranges() is None


def test_anchor_range_labels_that_name_no_pair_are_counted():
    from epp_ros.app import contract
    names = ['turret:cab', 'cab:turret', 'cab:cab', 'turret:boom', 'turret', 'a:b:c']
    matrix, unknown = contract.anchor_range_matrix(CONFIG.anchor_names, names,
                                                   [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    assert unknown == 4 and (matrix[0, 5], matrix[5, 0]) == (1.0, 2.0)
    assert np.isfinite(matrix).sum() == 2
    with pytest.raises(ValueError, match='2 names but 1 ranges'):
        contract.anchor_range_matrix(CONFIG.anchor_names, names[:2], [1.0])


def test_whole_lines_that_name_no_tag_count_their_source_tag_reported():
    assembler = FrameAssembler(CONFIG)
    line = [RangeRecord(anchor, 5.0) for anchor in ANCHORS[:-1]]
    assert assembler.add_line(line, 1.0, source_tag=TAGS[0], whole=True) == []
    # The same tag again, though with the pair it missed: the next cycle.
    (frame,) = assembler.add_line([RangeRecord(ANCHORS[-1], 6.0)], 1.01, source_tag=TAGS[0],
                                  whole=True)
    assert np.isfinite(frame.ranges[0, :-1]).all() and np.isnan(frame.ranges[0, -1])
    assert np.isnan(frame.ranges[1:]).all()


def test_a_whole_line_with_no_usable_range_does_not_count_its_tag_reported():
    assembler = FrameAssembler(CONFIG)
    assert assembler.add_line([RangeRecord(ANCHORS[0], 0.01, tag=TAGS[0])], 1.0,
                              whole=True) == []
    assert assembler.add_line([RangeRecord(ANCHORS[0], 5.0, tag=TAGS[0])], 1.01,
                              whole=True) == []
    (frame,) = assembler.poll(2.0)
    assert frame.stamp == 1.01 and assembler.dropped == {'implausible': 1}


def test_rx_power_of_tag_tag_ranges_is_not_entered():
    assembler = FrameAssembler(CONFIG)
    assembler.add(RangeRecord(TAGS[1], 7.2, tag=TAGS[0], rx_power_dbm=-80.0), 1.0)
    (frame,) = assembler.poll(2.0)
    assert frame.tag_ranges[0, 1] == 7.2 and np.isnan(frame.rx_power).all()
