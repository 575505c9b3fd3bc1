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

"""Numerical solvers: nearest EDM, EDM helpers, multilateration, SDP, one Levenberg–Marquardt."""
from .block_arrow import damped_step, eliminate, least_squares, normal_equations
from .edm import (align_to_known, centering_matrix, classical_mds, double_centre, gram_spectrum,
                  project_edm_cone, rank_penalty, refine_stress, squared_distances,
                  symmetric_eigh)
from .levenberg_marquardt import (levenberg_marquardt, levenberg_marquardt_batch,
                                  LevenbergMarquardtResult, marquardt_step)
from .multilateration import cold_start_guess, intersect_spheres, srls
from .nedm import nearest_edm, NearestEDMResult, project_constrained_edm, ProjectionResult
from .sdp import SDPLocalizer

__all__ = ['levenberg_marquardt', 'levenberg_marquardt_batch', 'LevenbergMarquardtResult',
           'marquardt_step',
           'normal_equations', 'eliminate', 'damped_step', 'least_squares', 'symmetric_eigh',
           'squared_distances', 'centering_matrix', 'double_centre', 'project_edm_cone',
           'gram_spectrum', 'rank_penalty', 'classical_mds', 'align_to_known', 'refine_stress',
           'srls',
           'intersect_spheres', 'cold_start_guess', 'nearest_edm', 'project_constrained_edm',
           'NearestEDMResult', 'ProjectionResult', 'SDPLocalizer']
