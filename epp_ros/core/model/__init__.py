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

"""The boom and its sensors: geometry, folds, the noise model, measurements, bounds."""
from .boom import BoomModel, MAX_RANGE_OFFSET
from .bounds import (bias_covariance, Bound, bound_from_covariance, bound_from_information, crlb,
                     fisher_information, posterior_crlb, posterior_information, RangeBiasPrior)
from .folds import (fold_alternatives, folded_angles, keep_folds, reflect, tip_circle,
                    tip_minima, TIP_PITCHES)
from .measurements import (Measurements, plausible_limits, range_spikes, Residuals, SensorNoise,
                           SPIKE_M, wrap_angle)
from .nlos import LinkLoss, NlosMixture, range_excess
from .noise import DEFAULT_NOISE, fitted_link_bias, link_bias_stds, NoiseModel
from .plane import fit_plane_to_ranges, fit_slew, from_plane, project_ranges, slew_step, to_plane
from .poses import boom_frames, boom_quaternions, rotation_to_quaternion

__all__ = ['BoomModel', 'MAX_RANGE_OFFSET', 'fisher_information', 'Bound', 'crlb',
           'bound_from_information', 'bound_from_covariance', 'RangeBiasPrior', 'bias_covariance',
           'posterior_information', 'posterior_crlb', 'SensorNoise', 'Measurements', 'Residuals',
           'plausible_limits', 'range_spikes', 'SPIKE_M', 'wrap_angle', 'NlosMixture', 'LinkLoss',
           'range_excess', 'NoiseModel', 'DEFAULT_NOISE', 'fitted_link_bias', 'link_bias_stds',
           'fit_slew', 'fit_plane_to_ranges', 'slew_step', 'to_plane', 'from_plane',
           'project_ranges', 'boom_frames', 'rotation_to_quaternion', 'boom_quaternions',
           'TIP_PITCHES', 'reflect',
           'fold_alternatives', 'folded_angles', 'keep_folds', 'tip_circle', 'tip_minima']
