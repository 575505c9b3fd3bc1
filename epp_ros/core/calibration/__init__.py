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

"""Offline calibration: anchors, offsets, links; its verdict; the survey."""
from .blockage import BlockageChain, DURATIONS
from .correlation import fit_noise_correlation, integrated_autocorrelation, NoiseCorrelation
from .fit import calibrate, CalibrationResult
from .survey import ANCHOR_TOLERANCE, AnchorPairs, OFFSET_TOLERANCE, survey_anchors, SurveyResult
from .verdict import (common_offset_std, CONDITION_LIMIT, implausible, link_offset_std, misfit,
                      MISFIT_RATIO, MISFIT_Z, PLAUSIBLE_OFFSET, poorly_determined,
                      scaled_covariance, verdict)

__all__ = ['BlockageChain', 'DURATIONS', 'CalibrationResult', 'calibrate', 'SurveyResult',
           'survey_anchors', 'AnchorPairs', 'ANCHOR_TOLERANCE', 'OFFSET_TOLERANCE',
           'CONDITION_LIMIT', 'MISFIT_RATIO', 'MISFIT_Z', 'PLAUSIBLE_OFFSET', 'scaled_covariance',
           'poorly_determined', 'link_offset_std', 'common_offset_std', 'implausible',
           'integrated_autocorrelation', 'NoiseCorrelation', 'fit_noise_correlation', 'misfit',
           'verdict']
