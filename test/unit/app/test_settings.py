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

"""The estimator's settings schema: one home for the node's and the tools' reading."""
from epp_ros.app.settings import estimator_settings, file_settings, parameter_name, SETTINGS
from epp_ros.cli import calibrate, urdf
from epp_ros.core.estimation.estimators import ESTIMATOR_OPTIONS
from epp_ros.core.estimation.integrity import IntegrityLimits
import pytest
from ros_processes import PUMP_YAML
import yaml


def document(**settings):
    """Return a pump.yaml document whose settings are the packaged ones and ``settings``."""
    parsed = yaml.safe_load(PUMP_YAML.read_text())
    parsed['/**']['ros__parameters'].update(settings)
    return parsed


def parameters(**settings):
    """Return the ``/**`` parameters of :func:`document`."""
    return document(**settings)['/**']['ros__parameters']


def test_a_files_settings_are_read_as_the_node_reads_them():
    read = file_settings({}, SETTINGS)
    assert read == {name: setting.default for name, setting in SETTINGS.items()}
    assert read['max_angular_rate'] == IntegrityLimits.max_angular_rate
    assert read['range_sigma'] == ESTIMATOR_OPTIONS['sigma']
    # An integer is a number; the packaged file's own values come through.
    assert file_settings(parameters(range_sigma=1), ['range_sigma']) == {'range_sigma': 1.0}
    assert file_settings(parameters(), ['max_angular_rate'])['max_angular_rate'] == 0.35


@pytest.mark.parametrize('name, value, says', [
    ('range_sigma', 0.0, r'range_sigma: must be in \[1e-06, 100\], got 0.0'),
    ('range_sigma', float('nan'), 'range_sigma: must be in'),
    ('range_sigma', 'big', "range_sigma: must be a number, got 'big'"),
    ('learn_noise', 'yes', "learn_noise: must be true or false, got 'yes'"),
    ('reset_after_failures', 2.5, 'reset_after_failures: must be an integer'),
    ('max_angular_rate', 1e3, r'max_angular_rate: must be in \[0.0001, 100\]'),
    ('nlos_fraction', True, 'nlos_fraction: must be a number, got True'),
])
def test_a_value_the_node_would_refuse_is_refused_everywhere(name, value, says):
    with pytest.raises(ValueError, match=says):
        file_settings(parameters(**{name: value}), [name])
    if name in ('range_sigma', 'learn_noise', 'nlos_fraction'):
        with pytest.raises(calibrate.CalibrationError, match=says):
            calibrate.noise_settings(document(**{name: value}))


def test_the_tools_take_the_schemas_defaults_and_names():
    told = calibrate.noise_settings({'/**': {'ros__parameters': {}}})
    assert told == {'sigma': SETTINGS['range_sigma'].default,
                    'tag_sigma': SETTINGS['tag_sigma'].default,
                    'nlos_fraction': SETTINGS['nlos_fraction'].default,
                    'nlos_gamma': SETTINGS['nlos_gamma'].default, 'learn_noise': True}
    assert urdf.configured_rate(PUMP_YAML) == 0.35
    options = estimator_settings({name: setting.default for name, setting in SETTINGS.items()})
    assert options['method'] == 'cepp' and options['sigma'] == SETTINGS['range_sigma'].default
    assert parameter_name('sigma: must be > 0') == 'range_sigma: must be > 0'


def test_estimator_options_read_a_file_as_the_node_does(tmp_path):
    from epp_ros.app.config import ConfigError
    from epp_ros.app.settings import estimator_options
    path = tmp_path / 'pump.yaml'
    path.write_text(yaml.safe_dump(document(method='chain', range_sigma=0.3, learn_noise=False,
                                            max_angular_rate=0.5, residual_error=3.0)))
    options = estimator_options(path)
    assert options['method'] == 'chain' and options['sigma'] == 0.3
    assert options['learn_noise'] is False and options['integrity'].max_angular_rate == 0.5
    assert options['thresholds'].residual_error == 3.0
    assert estimator_options(path, method='cepp')['method'] == 'cepp'
    assert estimator_options()['method'] == 'cepp'          # the packaged file's
    path.write_text(yaml.safe_dump(document(range_sigma=-1.0)))
    with pytest.raises(ConfigError, match=r'range_sigma: must be in \[1e-06, 100\]'):
        estimator_options(path)
    path.write_text(yaml.safe_dump(document(method='tpsm')))
    with pytest.raises(ConfigError, match='method'):
        estimator_options(path)
