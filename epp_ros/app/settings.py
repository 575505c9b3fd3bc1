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

"""
The posture estimator's settings: one schema for its node, the tools and pump.yaml.

Each setting's default, meaning, whether it can change while the node runs, and its range.
posture_estimator declares its parameters from :data:`SETTINGS`; the tools that read a
pump.yaml's settings (``epp_bag eval`` through :func:`estimator_options`, ``epp_urdf``,
``epp_calibrate``) read them through :func:`file_settings`, so a value means the same,
with the same default and range, wherever it is read. ROS-free: the node turns a
:class:`Setting` into its descriptor.
"""
from dataclasses import dataclass
import math

from epp_ros.core import RANGE_METHODS
from epp_ros.core.estimation import ESTIMATOR_OPTIONS
from epp_ros.core.estimation import IntegrityLimits, Thresholds

__all__ = ['Setting', 'SETTINGS', 'OPTION_OF', 'estimator_settings', 'parameter_name',
           'file_settings', 'estimator_options']


@dataclass(frozen=True)
class Setting:
    """
    One node parameter.

    Its default, what it means, whether it can change while running, and its range
    (inclusive, shown by ``ros2 param describe`` and enforced by ROS).
    """

    default: object
    description: str
    live: bool = True
    low: float = None
    high: float = None

    def checked(self, name, value):
        """
        Return ``value`` as this setting takes it, or raise ValueError naming ``name``.

        Of the default's type (an integer is a number too), within ``[low, high]``.
        """
        kind = type(self.default)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not kind:
            raise ValueError(f'{name}: must be {_kind_name(kind)}, got {value!r}')
        if self.low is not None and not (math.isfinite(value)
                                         and self.low <= value <= self.high):
            raise ValueError(f'{name}: must be in [{self.low:g}, {self.high:g}], got {value!r}')
        return value


def _kind_name(kind):
    return {bool: 'true or false', int: 'an integer', float: 'a number', str: 'a string',
            list: 'a list'}.get(kind, kind.__name__)


def _metres(name, description):
    """Declare a threshold in metres, its default from ``core.integrity.Thresholds``."""
    return Setting(getattr(Thresholds, name), description, True, 1e-6, 1e3)


def _told(option, description, low, high):
    """Declare what the estimator is told, its default from ``ESTIMATOR_OPTIONS``."""
    return Setting(float(ESTIMATOR_OPTIONS[option]), description, True, low, high)


#: The node's parameters. Thresholds are metres; a frame at ERROR is not published.
SETTINGS = {
    'method': Setting('cepp', f'Estimator: {", ".join(RANGE_METHODS)}; a change starts cold.'),
    'reset_after_failures': Setting(10, 'Frames in a row that cannot be solved or do not fit '
                                        'before the estimator starts cold.', True, 1, 100000),
    'publish_markers': Setting(True, 'Also publish arm_posture/markers for RViz.'),
    'learn_noise': Setting(True, 'Learn the range noise from the residuals while running, '
                                 'starting from range_sigma, nlos_fraction and nlos_gamma.'),
    'arm_length_warn': _metres('arm_length_warn', 'Section length or plane error for WARN, m.'),
    'arm_length_error': _metres('arm_length_error',
                                'Section length or plane error for ERROR, m.'),
    'residual_warn': _metres('residual_warn', 'Range residual RMS for WARN, m.'),
    'residual_error': _metres('residual_error', 'Range residual RMS for ERROR, m.'),
    'predicted_rmse_warn': _metres('predicted_rmse_warn',
                                   'Predicted RMSE (biases included) for WARN, m.'),
    'predicted_rmse_error': _metres('predicted_rmse_error', 'Predicted RMSE for ERROR, m.'),
    'range_sigma': _told('sigma', 'UWB range standard deviation, m.', 1e-6, 100.0),
    'nlos_fraction': _told('nlos_fraction', 'Prior probability that a range is NLOS.', 0.0,
                           0.99),
    'nlos_gamma': _told('nlos_gamma', 'Mean NLOS excess, m.', 1e-3, 100.0),
    'tag_sigma': _told('sigma', 'Tag-tag range standard deviation, m.', 1e-6, 100.0),
    'pitch_sigma': _told('pitch_sigma', 'Inclinometer standard deviation, rad.', 1e-6, 1.0),
    'slew_sigma': _told('slew_sigma', 'Slew encoder standard deviation, rad.', 1e-6, 1.0),
    'lowest_joint': _told('lowest_joint', 'No joint is below this height, m (ground z = 0).',
                          -1e3, 1e3),
    'link_bias_std': _told('link_bias_std', "Std of each range's own bias left after the "
                           'offsets (not averaged over frames), m; a pump description with '
                           'link_offset_std (calibrated) gives one per link instead.', 0.0,
                           10.0),
    'common_bias_std': _told('common_bias_std', 'Std of the bias common to all ranges left '
                             'after the offsets, m: adds to the predicted RMSE.', 0.0, 10.0),
    'bias_slope_std': _told('bias_slope_std', 'Std of the growth of that common bias with '
                            'range, m per m.', 0.0, 1.0),
    'anchor_std': _told('anchor_std', 'Std per axis of how far each anchor off the truck body '
                        '(not in body_anchors) may stand from where configured, m: adds to '
                        'the predicted RMSE; calibration writes what it leaves unknown.',
                        0.0, 10.0),
    'learn_anchors': Setting(False, 'Also learn how far each anchor off the truck body stands '
                                    'from where configured (with learn_noise): for calibrated '
                                    'links and outriggers not surveyed.'),
    'max_angular_rate': Setting(IntegrityLimits.max_angular_rate, 'Fastest slew or pitch '
                                'rate of the boom, rad/s: rules out jumps and folds.', True,
                                1e-4, 100.0),
    'slew_name': Setting('slew', 'boom_angles joint name of the slew encoder.', False),
    'pitch_names': Setting([], 'boom_angles joint names of the inclinometers, base outward '
                               '(default pitch1..pitchp).', False),
    'angle_max_age': Setting(0.2, 'Largest stamp difference between a range frame and its '
                                  'angles, s.', True, 1e-3, 60.0),
    'ranges_qos': Setting('reliable', 'QoS of the uwb/ranges subscription: reliable (keep '
                          'all: no frame lost unseen) or sensor_data (best effort, REP 2003, '
                          'for publishers that offer only that).', False),
}
#: Estimator options told by parameters of another name.
OPTION_OF = {'range_sigma': 'sigma', 'nlos_fraction': 'nlos_fraction',
             'nlos_gamma': 'nlos_gamma', 'tag_sigma': 'tag_sigma', 'pitch_sigma': 'pitch_sigma',
             'slew_sigma': 'slew_sigma', 'lowest_joint': 'lowest_joint',
             'link_bias_std': 'link_bias_std', 'common_bias_std': 'common_bias_std',
             'bias_slope_std': 'bias_slope_std', 'anchor_std': 'anchor_std'}


def parameter_name(message):
    """Say the node parameter where an estimator error names its option."""
    option = message.split(':', 1)[0]
    names = {option_name: parameter for parameter, option_name in OPTION_OF.items()}
    return message.replace(option, names[option], 1) if option in names else message


def estimator_settings(values):
    """
    Keyword arguments of PostureEstimator from the node's parameter values.

    Raises
    ------
    ValueError
        Naming the parameter, when a value cannot be used.

    """
    method = values['method']
    if method not in RANGE_METHODS:
        raise ValueError(f'method: {method!r} is not one of {RANGE_METHODS} (the node '
                         'receives UWB ranges only)')
    thresholds = Thresholds(**{name: values[name] for name in Thresholds.__dataclass_fields__})
    integrity = IntegrityLimits(max_angular_rate=values['max_angular_rate'])
    return dict(method=method, integrity=integrity, thresholds=thresholds,
                reset_after_failures=values['reset_after_failures'],
                learn_noise=values['learn_noise'], learn_anchors=values['learn_anchors'],
                **{OPTION_OF[name]: values[name] for name in OPTION_OF})


def file_settings(parameters, names):
    """
    Return the settings ``names`` of a pump.yaml, each its default where the file has none.

    Parameters
    ----------
    parameters : dict
        The file's ``/**`` ``ros__parameters`` (``config.read_parameters``).
    names : iterable of str
        Names in :data:`SETTINGS`.

    Raises
    ------
    ValueError
        Naming the first setting whose value the node would refuse.

    """
    return {name: SETTINGS[name].checked(name, parameters.get(name, SETTINGS[name].default))
            for name in names}


def estimator_options(path=None, method=None):
    """
    Return ``PostureEstimator``'s keyword arguments as posture_estimator reads a pump.yaml.

    Parameters
    ----------
    path : path, optional
        The parameters file; default: the packaged pump.yaml.
    method : str, optional
        Instead of the file's ``method``.

    Raises
    ------
    epp_ros.app.config.ConfigError
        On a file that cannot be read, or a setting the node would refuse, named.

    """
    from epp_ros.app.config import ConfigError, read_parameters
    try:
        values = file_settings(read_parameters(path), SETTINGS)
        if method is not None:
            values['method'] = method
        return estimator_settings(values)
    except ValueError as exc:
        raise ConfigError(f'{path or "pump.yaml"}: {parameter_name(str(exc))}') from None
