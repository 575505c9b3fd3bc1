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

"""The online estimator over its methods, integrity and learned noise."""
from .bias_learning import bias_design, BiasLearner, REFERENCE_RANGE
from .estimators import accepted_options, ESTIMATOR_OPTIONS, PostureEstimator
from .frame_policy import ADMIT, CLOCK_JUMP, FramePolicy, MALFORMED, OUT_OF_ORDER
from .integrity import ERROR, Integrity, IntegrityLimits, OK, Thresholds, Verdict, WARN
from .learned_errors import LearnedErrors, told_noise
from .methods import METHODS, RANGE_METHODS
from .metrics import COVERED_FRACTION, frame_rmse, joint_errors, pooled_rmse, wrong_frames, WRONG_M
from .noise_learning import frame_scale, NoiseLearner, RangeNoiseEstimate
from .posture_method import FrameResult, PostureMethod
from .reacquisition import Reacquisition

__all__ = ['BiasLearner', 'REFERENCE_RANGE', 'bias_design', 'PostureEstimator', 'METHODS',
           'RANGE_METHODS', 'ESTIMATOR_OPTIONS', 'accepted_options', 'FramePolicy', 'ADMIT',
           'OUT_OF_ORDER', 'CLOCK_JUMP', 'MALFORMED', 'OK', 'WARN', 'ERROR', 'Thresholds',
           'IntegrityLimits', 'Verdict', 'Integrity', 'joint_errors',
           'frame_rmse', 'pooled_rmse', 'wrong_frames', 'WRONG_M', 'COVERED_FRACTION',
           'RangeNoiseEstimate', 'NoiseLearner', 'frame_scale', 'PostureMethod', 'FrameResult',
           'LearnedErrors', 'told_noise', 'Reacquisition']
