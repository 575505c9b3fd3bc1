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

"""The posture methods: the paper's EPP1/EPP2/CEPP, our FieldCEPP, chain, track, baselines."""
from .baselines import SDPMethod, SRLSMethod, TPSMMethod
from .chain import (angles_from_joints, canonical_angles, ChainMethod, Fit, grow_chains,
                    SearchExhausted)
from .epp import CEPP, EPP1, EPP2
from .field_cepp import FieldCEPP
from .kernels import compile_fit
from .registry import make_method, method_options, METHODS, RANGE_METHODS
from .track import constant_velocity, Hypothesis, TrackMethod

__all__ = ['SRLSMethod', 'SDPMethod', 'TPSMMethod', 'ChainMethod', 'compile_fit', 'Fit',
           'SearchExhausted',
           'angles_from_joints', 'canonical_angles', 'grow_chains', 'EPP1', 'EPP2', 'CEPP',
           'FieldCEPP', 'METHODS', 'RANGE_METHODS', 'method_options', 'make_method',
           'TrackMethod', 'Hypothesis', 'constant_velocity']
