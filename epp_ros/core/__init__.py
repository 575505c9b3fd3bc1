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

"""Plain numerical library of epp_ros: geometry, estimators, simulation. No ROS imports."""
from epp_ros.core.calibration.fit import calibrate, CalibrationResult
from epp_ros.core.calibration.survey import survey_anchors, SurveyResult
from epp_ros.core.estimation.estimators import PostureEstimator
from epp_ros.core.estimation.methods.kernels import compile_fit
from epp_ros.core.estimation.methods.registry import METHODS, RANGE_METHODS
from epp_ros.core.model.boom import BoomModel
from epp_ros.core.solvers.nedm import nearest_edm

__all__ = ['BoomModel', 'PostureEstimator', 'METHODS', 'RANGE_METHODS', 'nearest_edm',
           'calibrate', 'CalibrationResult', 'survey_anchors', 'SurveyResult', 'compile_fit']
