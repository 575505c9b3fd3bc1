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

from pathlib import Path

from epp_ros.app.config import (ConfigError, load_pump_config, pump_config_from_parameters,
                                PUMP_PARAMETERS, Source)
from epp_ros.core import PostureEstimator
import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[3]
PUMP_YAML = ROOT / 'config' / 'pump.yaml'


def shared_values():
    values = yaml.safe_load(PUMP_YAML.read_text())['/**']['ros__parameters']
    return {name: value for name, value in values.items() if name in PUMP_PARAMETERS}


def test_pump_yaml_has_one_section_so_command_line_overrides_win():
    document = yaml.safe_load(PUMP_YAML.read_text())
    assert list(document) == ['/**']
    settings = document['/**']['ros__parameters']
    assert settings['method'] == 'cepp' and settings['frame_period'] == 0.1


def test_packaged_pump_description_loads():
    config = load_pump_config(PUMP_YAML)
    assert config.tag_names[0] == 'joint1' and len(config.anchor_ids) == 6
    assert config.sources == (Source('/dev/ttyUSB0', 'json', None),)
    assert config.link_names[:2] == ['joint1:turret', 'joint1:outrigger_fl']
    assert len(config.link_names) == 30
    model = config.model()
    np.testing.assert_allclose(model.anchors[1], [2.6, 3.4, 0.4])
    assert config.tag_index('3') == 2 and config.anchor_index('1782') == 0
    assert config.anchor_index('a1b2') is None


def test_labelled_ranges_are_arranged_by_name_in_any_order():
    config = load_pump_config(PUMP_YAML)
    names = ['joint5:cab', 'joint2:joint3', 'joint1:turret', 'crane:turret', 'joint3:joint2',
             'joint1:joint1']
    ranges, tag_ranges, unknown = config.link_matrices(names, [1.0, 7.1, 2.0, 3.0, 7.2, 0.0])
    assert ranges.shape == (5, 6) and tag_ranges.shape == (5, 5)
    assert ranges[4, 5] == 1.0 and ranges[0, 0] == 2.0 and np.isfinite(ranges).sum() == 2
    assert tag_ranges[1, 2] == 7.1 and tag_ranges[2, 1] == 7.2
    assert np.isfinite(tag_ranges).sum() == 2
    assert unknown == 2                      # no crane, and a tag does not range itself
    assert config.tag_link_name(1, 2) == 'joint2:joint3'
    with pytest.raises(ValueError, match='2 names but 1 ranges'):
        config.link_matrices(['joint1:turret', 'joint1:cab'], [1.0])


def test_range_ages_reduce_to_the_median_of_each_tags_known_ages():
    config = load_pump_config(PUMP_YAML)
    nan = float('nan')
    # Any order; joint2's ages 0.01, 0.03, 0.05 (median 0.03); the age of its missing range
    # and of a tag-tag range do not count; joint4 has only unknown ages.
    links = [('joint2:cab', 4.0, 0.05), ('joint1:turret', 2.0, 0.02),
             ('joint2:turret', 3.0, 0.01), ('joint2:outrigger_fl', nan, 0.9),
             ('joint2:joint3', 7.1, 0.5), ('joint2:outrigger_fr', 3.5, 0.03),
             ('joint4:turret', 5.0, -0.01), ('joint4:cab', 5.5, nan),
             ('joint4:outrigger_fl', 5.2, float('inf')), ('crane:turret', 1.0, 0.7)]
    names, values, ages = (list(column) for column in zip(*links))
    frame = config.link_frame(names, values, ages)
    assert frame.ages.shape == (5,) and frame.unknown == 1
    np.testing.assert_allclose(frame.ages[:2], [0.02, 0.03])
    assert np.isnan(frame.ages[2:]).all()
    ranges, tag_ranges, unknown = config.link_matrices(names, values)
    np.testing.assert_array_equal(frame.ranges, ranges)
    np.testing.assert_array_equal(frame.tag_ranges, tag_ranges)
    np.testing.assert_allclose(frame.range_stamps(100.0)[:2], [99.98, 99.97])
    assert np.isnan(frame.range_stamps(100.0)[2:]).all()


def test_a_message_without_ages_has_none_and_a_wrong_count_is_malformed():
    config = load_pump_config(PUMP_YAML)
    names, values = ['joint1:turret', 'joint1:cab'], [1.0, 2.0]
    for ages in (None, [], np.zeros(0)):
        frame = config.link_frame(names, values, ages)
        assert frame.ages is None and frame.range_stamps(5.0) is None
        assert frame.ranges[0, 0] == 1.0 and frame.ranges[0, 5] == 2.0
    with pytest.raises(ValueError, match='1 ages \\(effort\\) for 2 ranges'):
        config.link_frame(names, values, [0.01])
    with pytest.raises(ValueError, match='3 ages'):
        config.link_frame(names, values, [0.01, 0.02, 0.03])


def test_range_ages_round_trip_through_the_contract():
    from epp_ros.app import contract
    config = load_pump_config(PUMP_YAML)
    rng = np.random.default_rng(1)
    stamp = 1000.0
    received = stamp - rng.uniform(0.0, 0.1, size=(5, 6))
    received[3, :] = np.nan                                     # joint4 silent
    ranges = np.where(np.isfinite(received), 5.0, np.nan)
    effort = contract.range_ages(stamp, received.ravel())
    assert np.isnan(effort[18:24]).all() and (effort[np.isfinite(effort)] >= 0).all()
    order = rng.permutation(30)                                 # names in any order
    names = [config.link_names[i] for i in order]
    frame = config.link_frame(names, ranges.ravel()[order], effort[order])
    np.testing.assert_array_equal(frame.ranges, ranges)
    expected = np.median(stamp - received, axis=1)
    np.testing.assert_allclose(np.delete(frame.ages, 3), np.delete(expected, 3), atol=1e-9)
    assert np.isnan(frame.ages[3])
    np.testing.assert_allclose(np.delete(frame.range_stamps(stamp), 3),
                               np.delete(np.median(received, axis=1), 3), atol=1e-9)
    # A range received after the stamp (a clock step) is at the stamp, not in the future.
    assert contract.range_ages(stamp, [stamp + 0.5])[0] == 0.0


def test_default_path_finds_the_packaged_file():
    assert load_pump_config() == load_pump_config(PUMP_YAML)


def test_device_ids_compare_case_insensitively():
    values = shared_values()
    values['anchor_ids'] = ['a1', 'B2', 'c3', 'd4', 'E5', 'f6']
    config = pump_config_from_parameters(values)
    assert config.anchor_index('A1') == 0 and config.anchor_index(' f6 ') == 5


@pytest.mark.parametrize('change, field', [
    ({'tag_ids': ['1', '2', '3', '4', 'xyz']}, 'tag_ids'),
    ({'tag_ids': ['1', '2', '3', '4', '4']}, 'duplicate device ids'),
    ({'tag_ids': ['1', '2', '3', '4']}, 'tag_ids'),
    ({'tag_names': ['a', 'b', 'c', 'd', 'a']}, 'duplicate names'),
    ({'tag_names': ['a', 'b', 'c', 'd', 'e f']}, 'tag_names'),
    ({'anchor_names': []}, 'anchor_names'),
    ({'anchor_names': ['turret', 'joint2', 'a', 'b', 'c', 'd']}, 'also name tags'),
    ({'body_anchors': ['turret', 'boom']}, 'body_anchors'),
    ({'body_anchors': ['cab', 'cab']}, 'body_anchors'),
    ({'anchor_positions': [0.0] * 17}, 'anchor_positions'),
    ({'anchor_positions': ['x'] * 18}, 'anchor_positions'),
    ({'arm_lengths': [9.0, 7.0]}, 'arm_lengths'),
    ({'arm_lengths': [9.0, 7.0, 7.0, 9.0, -1.0]}, 'arm_lengths'),
    ({'base': [0.0, 0.0]}, 'base'),
    ({'pivot_offset': 'far'}, 'pivot_offset'),
    ({'pivot_offset': float('nan')}, 'pivot_offset'),
    ({'frame_id': ' '}, 'frame_id'),
    ({'source_protocols': ['morse']}, 'source_protocols'),
    ({'source_protocols': ['lec']}, 'source_tags'),
    ({'source_tags': ['9']}, 'source_tags'),
    ({'source_ports': ['']}, 'source_ports'),
    ({'source_ports': ['a', 'a'], 'source_protocols': ['json'] * 2,
      'source_tags': [''] * 2}, 'duplicate ports'),
    ({'source_tags': ['', '']}, 'one entry per source'),
    ({'colour': 'red'}, 'unknown pump parameter'),
])
def test_bad_descriptions_name_the_field(change, field):
    values = shared_values()
    values.update(change)
    with pytest.raises(ConfigError, match=field):
        pump_config_from_parameters(values)


def test_unreadable_files_give_one_clear_error(tmp_path):
    with pytest.raises(ConfigError, match='cannot read'):
        load_pump_config(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('uwb_driver: {ros__parameters: {baud: 9600}}\n')
    with pytest.raises(ConfigError, match='ros__parameters'):
        load_pump_config(bad)
    bad.write_text(': : [\n')
    with pytest.raises(ConfigError, match='cannot read'):
        load_pump_config(bad)


def test_pivot_offset_reaches_the_model():
    values = shared_values()
    values['pivot_offset'] = 0.8
    model = pump_config_from_parameters(values).model()
    assert model.pivot_offset == 0.8
    np.testing.assert_allclose(model.pivot(np.pi / 2), np.array(values['base']) + [0, 0.8, 0],
                               atol=1e-12)


def test_device_ids_compare_as_numbers_whatever_the_padding():
    values = shared_values()
    values['anchor_ids'] = ['0B82', '0x0081', '1784', '1785', '1786', '1787']
    config = pump_config_from_parameters(values)
    assert config.anchor_index('B82') == 0 and config.anchor_index('0xb82') == 0
    assert config.anchor_index('81') == 1 and config.anchor_index('0081') == 1
    assert config.anchor_index('B83') is None and config.anchor_index('not-hex') is None
    values['anchor_ids'] = ['0B82', 'B82', '1784', '1785', '1786', '1787']
    with pytest.raises(ConfigError, match='duplicate device ids'):
        pump_config_from_parameters(values)


@pytest.mark.parametrize('port', ['tcp-listen://0.0.0.0:80', 'tcp-listen://192.168.4.1:8080',
                                  'tcp-listen://[::1]:9000'])
def test_listening_sources_are_accepted(port):
    values = shared_values()
    values['source_ports'] = [port]
    assert pump_config_from_parameters(values).sources[0].port == port


@pytest.mark.parametrize('port', ['tcp-listen://:80', 'tcp-listen://0.0.0.0',
                                  'tcp-listen://0.0.0.0:0', 'tcp-listen://0.0.0.0:70000'])
def test_listening_sources_need_an_address_and_a_port(port):
    values = shared_values()
    values['source_ports'] = [port]
    with pytest.raises(ConfigError, match='source_ports'):
        pump_config_from_parameters(values)


def test_formats_that_name_no_device_need_the_source_anchor():
    values = shared_values()
    values.update(source_protocols=['bare'], source_tags=['0x1'])
    with pytest.raises(ConfigError, match='source_anchors'):
        pump_config_from_parameters(values)
    values['source_anchors'] = ['01782']
    assert pump_config_from_parameters(values).sources == (
        Source('/dev/ttyUSB0', 'bare', '1', '01782'),)
    values['source_anchors'] = ['9999']
    with pytest.raises(ConfigError, match='source_anchors'):
        pump_config_from_parameters(values)


def test_every_registered_format_is_a_protocol():
    from epp_ros.app.config import PROTOCOLS
    from epp_ros.uwb.formats import FORMATS
    assert PROTOCOLS == (*FORMATS, 'auto')


@pytest.mark.parametrize('positions, message', [
    ([1.0, 2.0, 3.0] * 6, 'same point'),
    ([0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.0, 0.0, 4.0, 0.0, 0.0, 5.0,
      0.0, 0.0, 6.0], 'one line'),
])
def test_coincident_or_collinear_anchors_are_refused(positions, message, tmp_path):
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters']['anchor_positions'] = positions
    path = tmp_path / 'pump.yaml'
    path.write_text(yaml.safe_dump(document))
    with pytest.raises(ConfigError, match=f'anchor_positions: .*{message}') as error:
        load_pump_config(path)
    assert '\n' not in str(error.value)


BOMB = """/**:
  ros__parameters:
    a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]
    b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]
    c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]
    d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]
    e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]
    f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e, *e]
    g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f, *f]
    h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g, *g]
    tag_names: [*h, *h, *h, *h, *h, *h, *h, *h, *h, *h]
"""


def test_a_yaml_alias_bomb_is_refused_at_once_with_one_short_line(tmp_path):
    path = tmp_path / 'bomb.yaml'
    path.write_text(BOMB)
    with pytest.raises(ConfigError, match='line 4: YAML aliases') as error:
        load_pump_config(path)
    assert len(str(error.value)) < 200 and '\n' not in str(error.value)


def test_an_oversized_file_is_refused(tmp_path):
    path = tmp_path / 'big.yaml'
    path.write_text(PUMP_YAML.read_text() + '#' * (2 << 20))
    with pytest.raises(ConfigError, match='at most'):
        load_pump_config(path)


@pytest.mark.parametrize('field', ['tag_names', 'arm_lengths', 'anchor_ids', 'source_tags'])
def test_error_messages_stay_short_whatever_the_value(field, tmp_path):
    document = yaml.safe_load(PUMP_YAML.read_text())
    document['/**']['ros__parameters'][field] = ['x y' * 500] * 500     # 750 kB
    path = tmp_path / 'long.yaml'
    path.write_text(yaml.safe_dump(document))
    with pytest.raises(ConfigError, match=field) as error:
        load_pump_config(path)
    assert len(str(error.value)) < 400


def test_device_offsets_are_optional_and_reach_the_model(tmp_path):
    assert load_pump_config(PUMP_YAML).model().has_offsets is False
    document = yaml.safe_load(PUMP_YAML.read_text())
    settings = document['/**']['ros__parameters']
    settings['anchor_offsets'] = [0.0, 0.12, -0.05, 0.08, 0.2, -0.1]
    settings['tag_offsets'] = [0.1, -0.03, 0.15, 0, -0.07]
    path = tmp_path / 'pump.yaml'
    path.write_text(yaml.safe_dump(document))
    model = load_pump_config(path).model()
    np.testing.assert_allclose(model.anchor_offsets, settings['anchor_offsets'])
    np.testing.assert_allclose(model.tag_offsets, settings['tag_offsets'])
    values = shared_values()
    values.update(anchor_offsets=[], tag_offsets=[])        # ROS parameters' "none"
    assert not pump_config_from_parameters(values).model().has_offsets
    # Each link's own offset, tag-major, as epp_calibrate writes it.
    values.update(pair_offsets=[0.001 * index for index in range(30)])
    model = pump_config_from_parameters(values).model()
    np.testing.assert_allclose(model.pair_offsets, np.arange(30).reshape(5, 6) * 0.001)
    np.testing.assert_allclose(model.link_offsets(), model.pair_offsets)


def test_what_a_calibration_leaves_unknown_of_each_link_becomes_the_estimators():
    values = shared_values()
    config = pump_config_from_parameters(values)
    settings = {'method': 'chain', 'link_bias_std': 0.1}
    assert config.link_offset_std is None and config.with_link_biases(settings) == settings
    values.update(link_offset_std=[0.01 + 0.001 * index for index in range(30)])
    config = pump_config_from_parameters(values)
    told = config.with_link_biases(settings)
    expected = 0.01 + 0.001 * np.arange(30).reshape(5, 6)        # tag-major rows
    np.testing.assert_allclose(told['link_bias_std'], expected)
    assert told['method'] == 'chain' and settings['link_bias_std'] == 0.1
    estimator = PostureEstimator(config.model(), **told)
    np.testing.assert_allclose(estimator.integrity.bias.link_std, expected)


@pytest.mark.parametrize('change, message', [
    ({'anchor_offsets': [0.1] * 5}, 'anchor_offsets: needs one offset per entry of '
                                    r'anchor_names \(6\) or none, got 5'),
    ({'tag_offsets': [0.1] * 6}, 'tag_offsets: needs one offset per entry of tag_names'),
    ({'tag_offsets': [0.1, 0.1, 0.1, 0.1, float('nan')]}, 'tag_offsets: must be finite'),
    ({'anchor_offsets': ['x'] * 6}, 'anchor_offsets: must be a list of numbers'),
    ({'anchor_offsets': [0.1] * 5 + [150.0]}, 'anchor_offsets: offsets must be within'),
    ({'tag_offsets': 0.1}, 'tag_offsets: must be a list'),
    ({'pair_offsets': [0.01] * 29}, r'pair_offsets: needs one offset per entry of tag_names x '
                                    r'anchor_names \(30\) or none, got 29'),
    ({'link_offset_std': [0.01] * 31}, r'link_offset_std: needs one offset per entry of '
                                       r'tag_names x anchor_names \(30\) or none, got 31'),
    ({'link_offset_std': [0.01] * 29 + [-0.01]}, 'link_offset_std: must be >= 0'),
])
def test_bad_offsets_give_one_line_naming_the_field(change, message):
    values = shared_values()
    values.update(change)
    with pytest.raises(ConfigError, match=message) as error:
        pump_config_from_parameters(values)
    assert '\n' not in str(error.value) and len(str(error.value)) < 200
