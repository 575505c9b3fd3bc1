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

"""The simulated pump: geometry, motion, range noise and field effects."""
from .link_errors import bias_at_range, LinkErrors, markov_step
from .simulate import (AngleNoise, BOOM_52M, FIELD_EFFECTS, field_effects, FieldEffects,
                       FieldFrame, FieldSimulator, JoystickMotion, make_motion, Motion, MOTIONS,
                       observe, random_posture, RangeNoise, simulate_field, StillMotion,
                       STOP_PROBABILITY, Trajectory, TRUCK_BODY_ANCHORS, truck_body_anchors,
                       truck_outriggers, truck_pump, working_cycle, WorkingMotion, XIE3DIM,
                       xie3dim)

__all__ = ['LinkErrors', 'bias_at_range', 'markov_step', 'XIE3DIM', 'xie3dim', 'truck_pump',
           'BOOM_52M', 'TRUCK_BODY_ANCHORS', 'truck_body_anchors', 'truck_outriggers',
           'random_posture', 'RangeNoise', 'AngleNoise', 'observe', 'Trajectory',
           'working_cycle', 'Motion', 'WorkingMotion', 'StillMotion', 'JoystickMotion',
           'STOP_PROBABILITY', 'MOTIONS', 'make_motion', 'FieldEffects', 'FIELD_EFFECTS',
           'field_effects', 'FieldFrame', 'FieldSimulator', 'simulate_field']
