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
What ``PostureEstimator`` asks of an estimation method, and what one frame gives back.

A method (``core.epp``, ``core.chain``, ``core.track``, ``core.baselines``) solves one frame
of :class:`~epp_ros.core.model.measurements.Measurements` from a prior posture;
``PostureEstimator`` cleans the frame, chooses the prior, judges the answer
(``core.integrity``) and reports a :class:`FrameResult`.
"""
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Optional, Protocol, runtime_checkable

from epp_ros.core.estimation.noise_learning import RangeNoiseEstimate
import numpy as np

__all__ = ['PostureMethod', 'FrameResult']


@runtime_checkable
class PostureMethod(Protocol):
    """
    A posture estimation method.

    Attributes
    ----------
    inputs : tuple of str
        What it uses of a frame: ``"ranges"``, ``"tag_ranges"``, ``"pitches"``,
        ``"slew"``, ``"range_stamps"``; the others are reported as ignored.
    prior : str
        ``"required"`` (it solves from a prior posture), ``"optional"`` (a prior is one
        more start) or ``"unused"``.
    holds_chain : bool
        Whether its answers are always a boom of p + 1 angles (the chain's bound is then
        their uncertainty).
    free_per_joint : int
        Of a method that does not hold the chain, the coordinates each joint's fit is
        free in (3; 2 where its arm length is held): with the chain's, what a frame's
        residuals lack (the integrity's chi-square). 3 where not said.

    Methods that can take the noise learned while running also have
    ``tune(*, sigma, eta, nlos_fraction, nlos_gamma, outlier_fraction)`` (the last the judge's
    share of outliers); methods with a state of their own (a motion model) have
    ``accept(info=None)``, called with the details of the solve whose fit the frame kept
    (None: the last solve's).

    """

    inputs: tuple
    prior: str
    holds_chain: bool

    def enough_information(self, measurements):
        """Return whether the frame can determine the posture."""

    def solve(self, measurements, prior, warm=False):
        """
        Return the joints (p, 3) of one frame and a dict of details.

        ``prior`` (p, 3) or None: the previous posture when ``warm``, else a guess.
        """

    def reset(self, joints=None):
        """Forget what was carried from frame to frame; ``joints`` (p, 3): start there."""


@dataclass
class FrameResult(Mapping):
    """
    What one frame gave: the decision, the method's answer, and how it was reached.

    Readable as a mapping (``result["valid"]``, ``result.get("chi_square")``), as
    ``last_diagnostics`` always was: the fields below by name, then every entry of
    ``details``. A field that is None (nothing solved) is absent from the mapping.
    """

    status: str                 #: ``"ok"``, or why the frame is not valid
    valid: bool                 #: the posture may be used
    level: int                  #: 0 OK, 1 WARN, 2 ERROR
    message: str
    method: str
    cold_start: bool            #: solved without a previous posture
    reacquired: bool            #: a fresh solve replaced a lost warm one
    noise: RangeNoiseEstimate   #: the range noise the frame was judged with
    estimate: Optional[np.ndarray] = None   #: (p, 3) the method's answer, valid or not
    #: (slew, pitches (p,)) radians: the chain nearest ``estimate``, as judged
    angles: Optional[tuple] = None
    converged: Optional[bool] = None        #: the solver met its tolerances
    iterations: Optional[int] = None        #: the solver's iterations
    solve_time: Optional[float] = None      #: seconds the frame took
    cold_restart: Optional[bool] = None     #: the warm start was dropped after failures
    # What was measured, and what was taken off it.
    missing_links: Optional[int] = None     #: tag-anchor ranges the frame lacked
    implausible_links: Optional[int] = None   #: ranges set aside as impossible
    ignored_inputs: Optional[list] = None   #: inputs the method does not use, by name
    range_bias: Optional[np.ndarray] = None   #: (2,) the common bias taken off: m, m/m
    anchor_shifts: Optional[dict] = None    #: {anchor: (3,) m}, each moving anchor's, seen
    # How well the answer fits, and how well it is known (the integrity checks').
    range_residual_rms: Optional[float] = None   #: m, fitted minus measured ranges
    section_lengths: Optional[np.ndarray] = None   #: (p,) m, of the answer
    arm_length_error: Optional[np.ndarray] = None  #: (p,) m, against the model's
    #: m, the bound at the answer, biases included, times the root of ``variance_factor``
    predicted_rmse: Optional[float] = None
    joint_std: Optional[np.ndarray] = None  #: (p,) m, each joint's predicted std
    noise_rmse: Optional[float] = None      #: m, the same without the common bias
    nlos_links: Optional[np.ndarray] = None   #: (p, m) bool, links judged NLOS
    outlier_links: Optional[np.ndarray] = None   #: (p, m) bool, links judged outliers
    chi_square: Optional[float] = None      #: the ranges' consistency statistic
    chi_square_limit: Optional[float] = None   #: its limit at the integrity's alpha
    chi_square_dof: Optional[float] = None  #: its degrees of freedom (links less fitted)
    #: max(1, chi_square / dof): the residuals' a-posteriori unit variance; the predicted
    #: stds are the bound times its square root
    variance_factor: Optional[float] = None
    ambiguous_joints: Optional[list] = None    #: joints (1-based) with another fit as good
    details: dict = field(default_factory=dict)   #: the method's and the checks' extras

    def _named(self):
        return [f.name for f in fields(self) if f.name != 'details'
                and getattr(self, f.name) is not None]

    def __getitem__(self, key):
        if key != 'details' and key in self.__dataclass_fields__:
            value = getattr(self, key)
            if value is None:
                raise KeyError(key)
            return value
        return self.details[key]

    def __iter__(self):
        yield from self._named()
        yield from (key for key in self.details if key not in self.__dataclass_fields__)

    def __len__(self):
        return sum(1 for _ in self)

    @classmethod
    def from_values(cls, values):
        """Build from a dict of every value: the named ones taken out, the rest details."""
        values = dict(values)
        named = {f.name: values.pop(f.name) for f in fields(cls)
                 if f.name != 'details' and f.name in values}
        return cls(**named, details=values)
