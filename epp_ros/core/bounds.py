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
The Cramér–Rao bound of the boom posture from UWB ranges (method notes section 5).

A pump boom is a chain: psi = (slew, pitch_1..pitch_p) fixes every joint. With independent
Gaussian range errors of standard deviation sigma_kj, the Fisher information of psi is
``F = A^T Sigma^-1 A``, ``A[(k, j), :] = u_kj^T dw_k/dpsi`` with ``u_kj`` the unit vector from
anchor j to tag k. Any unbiased estimator has ``cov(psi_hat) >= F^-1``; for the joints,
``cov(w_hat) >= G F^-1 G^T`` with ``G = dw/dpsi``, and the paper's RMSE is bounded below by
``sqrt(trace / p)``. Tag-tag ranges, inclinometers and a slew encoder add their own rows
to ``A`` (``core.measurements``).
"""
from dataclasses import dataclass

import numpy as np

from .measurements import Measurements, Residuals, SensorNoise

__all__ = ['fisher_information', 'Bound', 'crlb', 'bound_from_information']


def fisher_information(model, slew, pitches, sigma, measured=None):
    """
    Fisher information of psi, shape (p + 1, p + 1).

    Parameters
    ----------
    model : BoomModel
        The boom and its anchors.
    slew : float
        Radians.
    pitches : ndarray, shape (p,)
        Section pitches, radians.
    sigma : float, ndarray of shape (p, m), or SensorNoise
        Range standard deviations, metres, or the noise of every sensor.
    measured : ndarray of bool, shape (p, m), or Measurements, optional
        The tag-anchor links measured (all by default), or a frame whose finite entries
        (ranges, tag-tag ranges, inclinometers, slew encoder) say what is measured.

    """
    noise = sigma if isinstance(sigma, SensorNoise) else SensorNoise(range_sigma=sigma)
    if not isinstance(measured, Measurements):
        mask = np.ones((model.n_sections, model.n_anchors), bool) if measured is None \
            else np.asarray(measured, dtype=bool)
        measured = Measurements.ranges_only(np.where(mask, 1.0, np.nan))
    psi = np.r_[slew, pitches]
    jacobian = Residuals(model, measured, noise).jacobian(psi)
    return jacobian.T @ jacobian


@dataclass
class Bound:
    """The Cramér–Rao bound at one posture."""

    parameter_covariance: np.ndarray   #: (p + 1, p + 1) rad^2, of (slew, pitches)
    joint_covariance: np.ndarray       #: (p, 3, 3) m^2, of each joint
    rmse: float                        #: lower bound of the paper's RMSE, metres

    @property
    def joint_std(self):
        """Root of each joint's covariance trace, metres, shape (p,)."""
        return np.sqrt(np.trace(self.joint_covariance, axis1=-2, axis2=-1))


def crlb(model, slew, pitches, sigma, measured=None):
    """
    Cramér–Rao bound of the joints for a posture, anchor set and sensor noise.

    ``sigma`` and ``measured`` are as in :func:`fisher_information`.

    Returns
    -------
    Bound
        Infinite entries when the links do not determine the posture.

    """
    return bound_from_information(model, slew, pitches,
                                  fisher_information(model, slew, pitches, sigma, measured))


def bound_from_information(model, slew, pitches, information):
    """Return the :class:`Bound` at a posture from the Fisher information (p + 1, p + 1) of psi."""
    p = model.n_sections
    try:
        # One symmetric eigendecomposition gives both the conditioning and the inverse.
        eigenvalues, vectors = np.linalg.eigh(information)
    except np.linalg.LinAlgError:
        eigenvalues = np.zeros(p + 1)
    if not np.all(np.isfinite(eigenvalues)) or eigenvalues[0] <= 1e-14 * eigenvalues[-1]:
        infinite = np.full((p + 1, p + 1), np.inf)
        return Bound(infinite, np.full((p, 3, 3), np.inf), float('inf'))
    covariance = (vectors / eigenvalues) @ vectors.T
    jacobian = model.joint_jacobian(slew, pitches)
    joint_covariance = np.einsum('kcq,qr,kdr->kcd', jacobian, covariance, jacobian)
    rmse = float(np.sqrt(np.trace(joint_covariance, axis1=-2, axis2=-1).sum()
                         / model.n_sections))
    return Bound(covariance, joint_covariance, rmse)
