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
The paper's baselines behind the estimator interface: SR-LS, SDP and TPSM.

- ``srls``: each tag alone from its anchor ranges, SR-LS (Beck, Stoica & Li 2008).
- ``sdp``: the Biswas–Ye semidefinite relaxation of all tags (``core.sdp``); needs the
  optional cvxpy (a benchmark extra).
- ``tpsm``: the inclinometer method: forward kinematics of the measured slew and pitches,
  no ranges at all.

None of them uses the arm lengths, so their sections stretch and shrink with the noise
(the paper's Table 1); they are here to be compared with, not to run a pump.
"""
from epp_ros.core.solvers.multilateration import srls
import numpy as np

__all__ = ['SRLSMethod', 'SDPMethod', 'TPSMMethod']


class _PerTagMethod:
    """Shared by the range-only baselines: every tag needs ranges to anchors spanning 3-D."""

    prior = 'unused'
    inputs = ('ranges',)
    holds_chain = False         # each tag alone: each joint's own bound applies

    def __init__(self, model):
        self.model = model

    def enough_information(self, measurements):
        for valid in np.isfinite(measurements.ranges):
            if valid.sum() < 4:
                return False
            spread = self.model.anchors[valid] - self.model.anchors[valid].mean(axis=0)
            singular = np.linalg.svd(spread, compute_uv=False)
            if singular[2] <= 1e-3 * singular[0]:
                return False
        return True

    def reset(self, joints=None):
        """No state between frames."""


class SRLSMethod(_PerTagMethod):
    """Each tag located alone by SR-LS from its anchor ranges."""

    def solve(self, measurements, prior, warm=False):
        joints = np.empty((self.model.n_sections, 3))
        for k, row in enumerate(measurements.ranges):
            valid = np.isfinite(row)
            position = srls(self.model.anchors[valid], row[valid])
            if position is None:
                raise RuntimeError(f'the anchors ranged by tag {k + 1} do not span 3-D')
            joints[k] = position
        return joints, {'converged': True}


class SDPMethod(_PerTagMethod):
    """All tags by the Biswas–Ye SDP relaxation; builds the cvxpy problem once."""

    def __init__(self, model, solver='CLARABEL'):
        from epp_ros.core.solvers.sdp import SDPLocalizer
        super().__init__(model)
        self._localizer = SDPLocalizer(model.anchors, model.n_sections, solver=solver)

    def solve(self, measurements, prior, warm=False):
        joints, info = self._localizer.solve(measurements.ranges)
        return joints, {'converged': True, 'sdp_status': info['status'],
                        'sdp_objective': info['objective']}


class TPSMMethod:
    """Forward kinematics of the inclinometers' pitches and the slew encoder's angle."""

    prior = 'unused'
    inputs = ('pitches', 'slew')
    holds_chain = True          # the angles are the chain's

    def __init__(self, model):
        self.model = model

    def enough_information(self, measurements):
        return bool(np.isfinite(measurements.pitches).all() and np.isfinite(measurements.slew))

    def reset(self, joints=None):
        """No state between frames."""

    def solve(self, measurements, prior, warm=False):
        joints = self.model.forward_kinematics(measurements.slew, measurements.pitches)
        return joints, {'converged': True, 'slew': float(measurements.slew),
                        'pitches': measurements.pitches.copy()}
