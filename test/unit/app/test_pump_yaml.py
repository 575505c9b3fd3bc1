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

"""Writing a calibration back into pump.yaml: the values replaced, the file kept."""
from epp_ros.app.config import ConfigError, load_pump_config
from epp_ros.app.pump_yaml import update_pump_yaml
import numpy as np
import pytest
from ros_processes import PUMP_YAML
import yaml

CONFIG = load_pump_config(PUMP_YAML)


def test_update_pump_yaml_keeps_the_file_and_replaces_the_values(tmp_path):
    text = PUMP_YAML.read_text()
    anchors = np.array(CONFIG.anchor_positions)
    anchors[1] += [0.1234567, -0.2, 0.05]
    updated = update_pump_yaml(text, {'anchor_positions': anchors.ravel().tolist(),
                                      'anchor_offsets': [0.1, 0.0, -0.05, 0.0, 0.2, 1e-9],
                                      'tag_offsets': [0.01, 0.02, 0.03, 0.04, -0.05]})
    # Only the values changed: every comment and setting line is still there.
    changed = set(text.splitlines()) - set(updated.splitlines())
    assert changed == {' ' * 23 + '2.6, 3.4, 0.4,'}
    path = tmp_path / 'pump.yaml'
    path.write_text(updated)
    model = load_pump_config(path).model()
    np.testing.assert_allclose(model.anchors, anchors, atol=1e-6)
    np.testing.assert_allclose(model.anchor_offsets, [0.1, 0.0, -0.05, 0.0, 0.2, 0.0])
    # Replacing again edits in place.
    again = update_pump_yaml(updated, {'tag_offsets': [0.0] * 5})
    assert again.count('\n    tag_offsets: [') == 1
    assert 'tag_offsets: [0.0, 0.0, 0.0, 0.0, 0.0]' in again
    with pytest.raises(ConfigError, match='anchor_offsets'):
        update_pump_yaml(text, {'anchor_offsets': [0.1]})
    with pytest.raises(ConfigError, match='unknown'):
        update_pump_yaml(text, {'anchors': [0.1]})
    # The estimator's settings a calibration determines: numbers, replaced in place.
    told = update_pump_yaml(text, {'link_bias_std': 0.0123, 'common_bias_std': 0.004})
    assert set(told.splitlines()) - set(text.splitlines()) == {
        '    link_bias_std: 0.0123', '    common_bias_std: 0.004'}
    with pytest.raises(ConfigError, match='link_bias_std: must be a finite number >= 0'):
        update_pump_yaml(text, {'link_bias_std': -0.1})
    # Per-link lists, tag-major: one tag's links a line, read back as written.
    stds = [0.01 * (k + 1) + 0.001 * j for k in range(5) for j in range(6)]
    per_link = update_pump_yaml(text, {'link_offset_std': stds, 'pair_offsets': [0.0] * 30})
    for name in ('link_offset_std', 'pair_offsets'):
        start = per_link.index(f'    {name}: [')
        written = per_link[start:per_link.index(']', start) + 1]
        assert written.count('\n') == 4                  # five tags, five lines
    parsed = yaml.safe_load(per_link)['/**']['ros__parameters']
    assert parsed['link_offset_std'] == pytest.approx(stds, abs=1e-6)
