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

A tracker that models the motion does better than one frame allows. For a state ``x``
(here ``(psi, psi_dot)``) that moves as ``x_k+1 = F x_k + w_k``, ``w_k ~ N(0, Q)``, the
posterior Cramér–Rao bound (Tichavský, Muravchik & Nehorai 1998) bounds the error of any
estimator of ``x_k`` from the frames up to k by ``J_k^-1``, where
``J_k+1 = (F J_k^-1 F^T + Q)^-1 + M_k+1`` and ``M_k`` is frame k's Fisher information of
the state (the single-frame information of psi, none of the rates). It is computed in
information form, ``(F J^-1 F^T + Q)^-1 = R^T (I + R Q R^T)^-1 R`` with ``R^T R = F^-T J F^-1``,
which needs neither ``J`` nor ``Q`` to be invertible: a flat prior, a frame that leaves a
direction unmeasured and a noiseless direction of the motion are all exact. For a linear
Gaussian model the Kalman filter attains the bound; with a constant-velocity model of the
boom it falls below the single-frame bound, tends to it as the process noise grows, and
stays finite through a frame with too few links.

Real ranges also carry biases that calibration does not remove exactly (a link's own term,
growth with range, the tag's orientation; ``core.link_errors``). They are constant over
frames, so no residual test sees the part of them a fit absorbs, and the bound above is
then too small: a fit weighted by ``Sigma^-1`` moves by ``F^-1 A^T Sigma^-1 b`` for range
biases ``b``. With ``b ~ N(0, B)`` (:class:`RangeBiasPrior`: a common part and a part of
each link's own), the error covariance is ``F^-1 + F^-1 A^T Sigma^-1 B Sigma^-1 A F^-1``
(:func:`bias_covariance`), which no number of frames reduces. Within one frame a link's
own part is one more independent error per range (``B = l^2 I`` only widens sigma); the
common part is what a fit absorbs.
"""
from dataclasses import dataclass
import math

from epp_ros.core.model.measurements import Measurements, Residuals, SensorNoise
from epp_ros.core.solvers.compiled import kernel
import numpy as np

__all__ = ['fisher_information', 'Bound', 'crlb', 'bound_from_information', 'frame_bounds',
           'bound_from_covariance', 'RangeBiasPrior', 'bias_covariance',
           'uncontrolled_covariance', 'POORLY_CONTROLLED', 'posterior_information',
           'posterior_crlb']


@dataclass(frozen=True, eq=False)
class RangeBiasPrior:
    """
    What is not known of the biases left in the tag-anchor ranges.

    A range ``r`` has the systematic error ``c + s (r - r0) + e_kj``: ``c ~ N(0,
    common_std^2)`` (metres) and ``s ~ N(0, slope_std^2)`` (metres per metre, about ``r0 =
    core.bias_learning.REFERENCE_RANGE``) shared by every link, ``e_kj ~ N(0, link_std^2)``
    each link's own; all constant over frames. Zero: the ranges are unbiased once the
    model's offsets are taken off (the simulator's pumps). Uncalibrated DW1000-class links
    have a common part of ~0.2-0.4 m at a boom's ranges, growing by ~1 cm per metre, and
    ~0.1 m of each link's own (``simulate.FIELD_EFFECTS['real_uwb']``). ``link_std`` may
    also be one per link, shape (p, m): what a calibration leaves unknown of each.

    An anchor in ``moving`` (off the truck body) may stand up to ``anchor_std`` (metres, per
    axis) from where configured: each of its ranges then carries ``-u . delta``, ``u`` the
    unit vector from the anchor to the tag (``core.estimation.bias_learning``).
    """

    link_std: float = 0.0
    common_std: float = 0.0
    slope_std: float = 0.0
    anchor_std: float = 0.0
    moving: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, 'moving', tuple(int(j) for j in self.moving))
        if np.ndim(self.link_std) == 2:
            per_link = np.array(self.link_std, dtype=float)
            if not np.all(np.isfinite(per_link) & (per_link >= 0)):
                raise ValueError(f'link_std: must be finite and >= 0, got {self.link_std!r}')
            per_link.flags.writeable = False
            object.__setattr__(self, 'link_std', per_link)
        for name in ('link_std', 'common_std', 'slope_std', 'anchor_std')[
                np.ndim(self.link_std) == 2:]:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                                 np.floating)) \
                    or not np.isfinite(value) or value < 0:
                raise ValueError(f'{name}: must be a finite number >= 0, got {value!r}')
            object.__setattr__(self, name, float(value))

    def __bool__(self):
        """Whether any bias is unknown."""
        return bool(np.any(self.link_std)) or self.common_std > 0 or self.slope_std > 0 or (
            self.anchor_std > 0 and bool(self.moving))

    def common_covariance(self):
        """
        Return the covariance (q, q) of the common offset (m), slope (m/m), anchor shifts (m).

        ``q = 2 + 3 len(moving)``, as ``bias_learning.bias_design``'s columns.
        """
        anchors = [self.anchor_std ** 2] * (3 * len(self.moving))
        return np.diag([self.common_std ** 2, self.slope_std ** 2, *anchors])


#: The compiled twin of :func:`frame_bounds` (``solvers.compiled``).
KERNEL = 'epp_ros.core.model.compiled_bounds'
#: The smallest eigenvalue of a Fisher information, over its largest, that determines psi.
DETERMINED = 1e-14
#: The redundancy number a poorly controlled link's increase is divided by, at least.
LEAST_REDUNDANCY = 1e-12
#: Redundancy number (the share of a link's error its residual shows) under which the
#: other measurements barely check it: geodesy's "poorly controlled" observation.
POORLY_CONTROLLED = 0.3


def uncontrolled_covariance(jacobian, information_inverse, floor=POORLY_CONTROLLED):
    """
    Return the covariance (p + 1, p + 1) the poorly controlled links' possible errors add.

    A link whose redundancy number ``r = 1 - a F^-1 a^T`` is under ``floor`` hides most
    of any error of its own in the fit (a blocked link taken in whole, a bias of the
    pair): the other measurements barely check it. For each, what leaving it out would
    add to the fit's covariance, ``F^-1 a^T a F^-1 / r`` (Sherman–Morrison: exactly the
    leave-one-out increase), is added. One such link wrong at a time: the sum is at least
    each one's increase, not the covariance of leaving several out. It covers where the
    fit would go without the link, not an error of any size. A link nothing else checks
    (``r`` near 0) makes it as large as the fit cannot see (a frame then unobservable).

    Parameters
    ----------
    jacobian : ndarray, shape (n, p + 1)
        The scaled rows (divided by their sigma) of the links in question.
    information_inverse : ndarray, shape (p + 1, p + 1)
        ``F^-1`` of every row of the fit, those included.
    floor : float
        Redundancy numbers under this count.

    Returns
    -------
    ndarray, shape (p + 1, p + 1)
        Added to ``F^-1``, rad^2: zero where no link is under ``floor``.

    """
    through = jacobian @ information_inverse                                  # (n, q)
    redundancy = 1.0 - np.einsum('iq,iq->i', through, jacobian)
    poor = redundancy < floor
    if not poor.any():
        return np.zeros_like(information_inverse)
    shares = np.maximum(redundancy[poor], LEAST_REDUNDANCY)
    return (through[poor].T / shares) @ through[poor]


def bias_covariance(jacobian, sigma, links, information_inverse, link_std=0.0, common=None):
    """
    Return the covariance (p + 1, p + 1) range biases add to a weighted fit of psi.

    Parameters
    ----------
    jacobian : ndarray, shape (n, p + 1)
        Of the scaled residuals (rows divided by ``sigma``), as ``Residuals.jacobian``.
    sigma : ndarray, shape (n,)
        Each row's standard deviation (the fit's weights are ``sigma^-2``).
    links : ndarray of bool, shape (n,)
        The rows that are tag-anchor ranges (the biased ones).
    information_inverse : ndarray, shape (p + 1, p + 1)
        ``F^-1`` of the same rows.
    link_std : float
        Standard deviation of each link's own bias, metres.
    common : tuple (ndarray (L, k), ndarray (k, k)), optional
        The common bias: its directions over the L link rows (the bias of link row i is
        ``design[i] @ beta``) and the covariance of ``beta``.

    Returns
    -------
    ndarray, shape (p + 1, p + 1)
        ``F^-1 M B M^T F^-1`` with ``M = A^T Sigma^-1`` over the link rows and
        ``B = link_std^2 I + design C design^T``.

    """
    mapped = information_inverse @ (jacobian[links] / np.asarray(sigma)[links, None]).T
    added = link_std ** 2 * mapped @ mapped.T
    if common is not None:
        design, covariance = common
        through = mapped @ design
        added = added + through @ covariance @ through.T
    return added


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

    def direction_std(self, pitches):
        """
        Return the standard deviation of each section's direction, radians, shape (p,).

        A section turns with its pitch and, at right angles, with the slew times the cosine
        of its ``pitches`` (p,) (radians): the root of the two variances' sum. Infinite
        where the bound is.
        """
        covariance = self.parameter_covariance
        variance = np.diagonal(covariance)[1:] + np.cos(pitches) ** 2 * covariance[0, 0]
        return np.sqrt(np.where(np.isnan(variance), np.inf, variance))


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


def bound_from_information(model, slew, pitches, information, joint_jacobian=None):
    """
    Return the :class:`Bound` at a posture from the Fisher information (p + 1, p + 1) of psi.

    ``joint_jacobian`` (p, 3, p + 1): ``model.joint_jacobian(slew, pitches)``, when the
    caller has it already.
    """
    p = model.n_sections
    try:
        # One symmetric eigendecomposition gives both the conditioning and the inverse.
        eigenvalues, vectors = np.linalg.eigh(information)
    except np.linalg.LinAlgError:
        eigenvalues = np.zeros(p + 1)
    if not np.all(np.isfinite(eigenvalues)) or eigenvalues[0] <= DETERMINED * eigenvalues[-1]:
        return _unbounded(p)
    return bound_from_covariance(model, slew, pitches, (vectors / eigenvalues) @ vectors.T,
                                 joint_jacobian)


def bound_from_covariance(model, slew, pitches, covariance, joint_jacobian=None):
    """
    Return the :class:`Bound` at a posture of psi's covariance (p + 1, p + 1), rad^2.

    ``joint_jacobian`` as in :func:`bound_from_information`. Infinite where a joint's
    variance comes out negative or NaN: the covariance is then so large in some direction
    (a link nothing checks, :func:`uncontrolled_covariance`) that its rounding exceeds
    what it says of that joint, and it says nothing.
    """
    jacobian = model.joint_jacobian(slew, pitches) if joint_jacobian is None \
        else joint_jacobian
    joint_covariance = np.einsum('kcq,qr,kdr->kcd', jacobian, covariance, jacobian)
    return _bound(model, covariance, joint_covariance)


def frame_bounds(model, residuals, psi, common=None, floor=POORLY_CONTROLLED):
    """
    Return a fit's bound, the bound widened by what its links may hide, and the link rows.

    The Cramér–Rao bound at ``psi`` from every row of ``residuals``; then that bound with
    what the poorly controlled links could hide (:func:`uncontrolled_covariance` at
    ``floor``) and the common bias could add (:func:`bias_covariance`) added: the same
    :class:`Bound` object when nothing is added or the first is infinite.

    Parameters
    ----------
    model : BoomModel
        The boom and the anchors.
    residuals : Residuals
        The rows counted: the frame's links taken as line-of-sight, and its angle sensors.
    psi : ndarray, shape (p + 1,)
        The estimate's slew and pitches, radians.
    common : (ndarray, ndarray), optional
        The common bias: its directions over the tag-anchor rows (n_links, k) and its
        covariance (k, k), as :func:`bias_covariance`'s ``common``.
    floor : float
        :func:`uncontrolled_covariance`'s.

    Returns
    -------
    random, total : Bound
    rows : ndarray, shape (n_links, p + 1)
        The tag-anchor rows of the Jacobian, unscaled (``Residuals.rows``).

    """
    compiled = kernel(KERNEL)
    if compiled is not None:
        try:
            return _from_kernel(model, compiled,
                                *compiled.frame_bounds(model, residuals, psi, common, floor))
        except np.linalg.LinAlgError:       # its eigendecomposition failed: numpy's says
            pass
    joint_jacobian = model.joint_jacobian(psi[0], psi[1:])
    rows = residuals.rows(psi, joint_jacobian=joint_jacobian)
    jacobian = rows / residuals.sigma[:, None]
    random = bound_from_information(model, psi[0], psi[1:], jacobian.T @ jacobian,
                                    joint_jacobian)
    n_links = np.count_nonzero(residuals.link_mask)
    if not math.isfinite(random.rmse):
        return random, random, rows[:n_links]
    added = uncontrolled_covariance(jacobian[:n_links], random.parameter_covariance, floor)
    if common is not None:
        links = np.arange(residuals.size) < n_links
        added = added + bias_covariance(jacobian, residuals.sigma, links,
                                        random.parameter_covariance, common=common)
    if not added.any():
        return random, random, rows[:n_links]
    return random, bound_from_covariance(model, psi[0], psi[1:],
                                         random.parameter_covariance + added,
                                         joint_jacobian), rows[:n_links]


def _from_kernel(model, compiled, state, random, random_joint, total, total_joint, rows):
    """Return :func:`frame_bounds`' answer from its kernel's, ``compiled``'s."""
    p = model.n_sections
    if state == compiled.UNBOUNDED:
        unbounded = _unbounded(p)
        return unbounded, unbounded, rows
    first = _bound(model, random, random_joint)
    if state == compiled.RANDOM_ONLY or not math.isfinite(first.rmse):
        return first, first, rows
    return first, _bound(model, total, total_joint), rows


def _bound(model, covariance, joint_covariance):
    """Return the :class:`Bound` of psi's and the joints' covariances; infinite, see above."""
    variances = np.trace(joint_covariance, axis1=-2, axis2=-1)
    if not np.all(variances >= 0.0):
        return _unbounded(model.n_sections)
    return Bound(covariance, joint_covariance, float(np.sqrt(variances.sum() / model.n_sections)))


def _unbounded(p):
    """Return the :class:`Bound` of a posture the measurements do not determine."""
    return Bound(np.full((p + 1, p + 1), np.inf), np.full((p, 3, 3), np.inf), float('inf'))


def _square_matrix(value, name, size=None):
    """Finite float array of shape (n, n) (n = ``size`` when given); ValueError otherwise."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name} must be a numeric square matrix') from exc
    if array.ndim != 2 or array.shape[0] != array.shape[1] \
            or (size is not None and array.shape[0] != size):
        expected = '(n, n)' if size is None else f'({size}, {size})'
        raise ValueError(f'{name} must have shape {expected}, got {array.shape}')
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be finite')
    return array


def _check_psd(matrix, name):
    """Raise ValueError unless ``matrix`` (n, n) is symmetric positive semi-definite."""
    scale = max(float(np.abs(matrix).max(initial=0.0)), np.finfo(float).tiny)
    tolerance = 1e-9 * scale
    if np.abs(matrix - matrix.T).max(initial=0.0) > tolerance:
        raise ValueError(f'{name} must be symmetric')
    if np.linalg.eigvalsh(matrix).min(initial=0.0) < -tolerance:
        raise ValueError(f'{name} must be positive semi-definite')


def _symmetric_root(matrix):
    """Return ``R`` (n, n) with ``R^T R = matrix`` for a symmetric PSD matrix (any rank)."""
    eigenvalues, vectors = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return np.sqrt(np.clip(eigenvalues, 0.0, None))[:, None] * vectors.T


def posterior_information(transition, process_covariance, measurement_information,
                          initial_information):
    """
    Posterior Fisher information of the state of a linear motion model, frame by frame.

    The state moves as ``x_k+1 = F x_k + w_k``, ``w_k ~ N(0, Q)``; frame 0 is measured at
    the start, where the prior applies, so ``J_0 = J_prior + M_0`` and
    ``J_k+1 = (F J_k^-1 F^T + Q)^-1 + M_k+1`` (Tichavský, Muravchik & Nehorai 1998, additive
    Gaussian process noise). ``J_k^-1`` bounds the error covariance of any estimator of
    ``x_k`` from frames 0..k.

    The prediction is computed as ``R^T (I + R Q R^T)^-1 R`` with ``R^T R = F^-T J_k F^-1``
    (``R`` from a symmetric eigendecomposition, ``(I + R Q R^T)`` inverted through its own):
    the same matrix as the covariance form when everything is invertible, but neither
    ``J_k`` nor ``Q`` is ever inverted and the result is positive semi-definite by
    construction. So a singular or zero ``initial_information`` (a flat prior), frames
    that leave directions unmeasured (a singular ``J_k``: those directions simply carry no
    information forward) and a singular ``Q`` (directions that move without noise) are
    handled exactly, with no pseudo-inverse threshold.

    Parameters
    ----------
    transition : array_like, shape (n, n)
        ``F``, the state transition from one frame to the next; must be invertible.
    process_covariance : array_like, shape (n, n)
        ``Q``, the covariance of the process noise added per step; symmetric positive
        semi-definite (it may be singular).
    measurement_information : array_like, shape (T, n, n)
        ``M_k``, each frame's expected Fisher information of the state from that frame's
        measurements; symmetric positive semi-definite.
    initial_information : array_like, shape (n, n)
        The prior's information about the state at frame 0, before its measurements;
        symmetric positive semi-definite (zero for no prior).

    Returns
    -------
    ndarray, shape (T, n, n)
        ``J_k``, the information after frame k's measurements, in the units of
        ``measurement_information``.

    Raises
    ------
    ValueError
        On a wrong shape, a non-finite entry, an asymmetric or indefinite covariance or
        information, or a singular ``transition``, naming the argument.

    """
    transition = _square_matrix(transition, 'transition')
    n = transition.shape[0]
    process_covariance = _square_matrix(process_covariance, 'process_covariance', n)
    initial_information = _square_matrix(initial_information, 'initial_information', n)
    try:
        information = np.array(measurement_information, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError('measurement_information must be a numeric array '
                         f'of shape (T, {n}, {n})') from exc
    if information.ndim != 3 or information.shape[1:] != (n, n):
        raise ValueError(f'measurement_information must have shape (T, {n}, {n}), '
                         f'got {information.shape}')
    if not np.all(np.isfinite(information)):
        raise ValueError('measurement_information must be finite')
    _check_psd(process_covariance, 'process_covariance')
    _check_psd(initial_information, 'initial_information')
    for k, frame in enumerate(information):
        _check_psd(frame, f'measurement_information[{k}]')
    singular = np.linalg.svd(transition, compute_uv=False)
    if not singular[-1] > 1e-12 * singular[0]:
        raise ValueError('transition must be invertible')

    posterior = np.empty_like(information)
    current = initial_information
    identity = np.eye(n)
    for k, frame in enumerate(information):
        if k:
            # R^T R = F^-T J F^-1, the information of F x; then add Q in covariance terms.
            root = np.linalg.solve(transition.T, _symmetric_root(current).T).T
            spread = root @ process_covariance @ root.T
            eigenvalues, vectors = np.linalg.eigh(identity + 0.5 * (spread + spread.T))
            projected = vectors.T @ root
            current = projected.T @ (projected / eigenvalues[:, None])
        current = current + frame
        current = 0.5 * (current + current.T)
        posterior[k] = current
    return posterior


def _marginal_information(information, size):
    """
    Information (size, size) of the first ``size`` states with the others unknown.

    The Schur complement ``J_aa - J_ab J_bb^+ J_ba``: the inverse of the leading block of
    ``J^-1`` when ``J`` is invertible, and still the right answer when the remaining
    states are undetermined (e.g. the rates at the first frame with no prior).
    """
    leading, cross, rest = information[:size, :size], information[:size, size:], \
        information[size:, size:]
    eigenvalues, vectors = np.linalg.eigh(rest)
    largest = max(float(np.abs(eigenvalues).max(initial=0.0)), np.finfo(float).tiny)
    kept = eigenvalues > 1e-12 * largest
    whitened = (cross @ vectors[:, kept]) / np.sqrt(eigenvalues[kept])
    marginal = leading - whitened @ whitened.T
    return 0.5 * (marginal + marginal.T)


def posterior_crlb(model, slew, pitches, sigma, frame_period, process_noise, measured=None,
                   initial_information=None):
    """
    Posterior Cramér–Rao bound of the joints along a trajectory, for a constant-velocity model.

    The state is ``x = (psi, psi_dot)``, shape (2 (p + 1),): every angle moves at a rate
    driven by white angular acceleration of spectral density ``q``, so from one frame to
    the next ``F = [[I, dt I], [0, I]]`` and ``Q = [[dt^3/3, dt^2/2], [dt^2/2, dt]] (x) diag(q)``.
    Each frame's measurements inform psi alone (:func:`fisher_information`); the motion
    model links the frames (:func:`posterior_information`).

    Parameters
    ----------
    model : BoomModel
        The boom and its anchors.
    slew : array_like, shape (T,)
        The true slew at each frame, radians.
    pitches : array_like, shape (T, p)
        The true section pitches at each frame, radians.
    sigma : float, ndarray of shape (p, m), or SensorNoise
        As in :func:`fisher_information`.
    frame_period : float
        ``dt``, seconds between frames; > 0.
    process_noise : float or array_like, shape (p + 1,)
        ``q``, rad^2/s^3: one for every angle, or one per angle (slew first); >= 0.
    measured : array_like of bool, shape (p, m) or (T, p, m), optional
        The tag-anchor links measured: every frame the same, or per frame (all by default).
    initial_information : array_like, shape (2 (p + 1), 2 (p + 1)), optional
        The prior's information about ``(psi, psi_dot)`` at the first frame, in rad^-2 and
        (rad/s)^-2 (none by default: the first frame's bound is then the single-frame one).

    Returns
    -------
    list of Bound
        One per frame, from the psi-marginal of ``J_k`` (the rates left free). A frame whose
        posterior does not determine psi gets infinite entries, as :func:`crlb` does.

    Raises
    ------
    ValueError
        On a wrong shape or a non-finite value, ``frame_period <= 0`` or a negative
        ``process_noise``, naming the argument.

    """
    p, m = model.n_sections, model.n_anchors
    size = p + 1
    slew, pitches = _checked_trajectory(slew, pitches, p)
    frames = slew.size
    dt = _checked_period(frame_period)
    q = _checked_process_noise(process_noise, size)
    masks = _link_masks(measured, frames, p, m)
    if initial_information is None:
        initial_information = np.zeros((2 * size, 2 * size))
    else:
        initial_information = _square_matrix(initial_information, 'initial_information',
                                             2 * size)

    identity = np.eye(size)
    transition = np.block([[identity, dt * identity], [np.zeros((size, size)), identity]])
    process_covariance = np.kron(np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]]),
                                 np.diag(np.broadcast_to(q, (size,))))
    information = np.zeros((frames, 2 * size, 2 * size))
    for k in range(frames):
        information[k, :size, :size] = fisher_information(model, slew[k], pitches[k], sigma,
                                                          masks[k])
    posterior = posterior_information(transition, process_covariance, information,
                                      initial_information)
    return [bound_from_information(model, slew[k], pitches[k],
                                   _marginal_information(posterior[k], size))
            for k in range(frames)]


def _checked_trajectory(slew, pitches, p):
    """Return slew (T,) and pitches (T, p) as finite float arrays; ValueError otherwise."""
    try:
        slew = np.array(slew, dtype=float)
        pitches = np.array(pitches, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError('slew and pitches must be numeric arrays') from exc
    if slew.ndim != 1:
        raise ValueError(f'slew must have shape (T,), got {slew.shape}')
    if pitches.shape != (slew.size, p):
        raise ValueError(f'pitches must have shape ({slew.size}, {p}), got {pitches.shape}')
    if not (np.all(np.isfinite(slew)) and np.all(np.isfinite(pitches))):
        raise ValueError('slew and pitches must be finite')
    return slew, pitches


def _checked_period(frame_period):
    """Return the frame period as a float > 0, seconds; ValueError otherwise."""
    try:
        dt = float(frame_period)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'frame_period must be a number, got {frame_period!r}') from exc
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f'frame_period must be finite and > 0, got {frame_period!r}')
    return dt


def _checked_process_noise(process_noise, size):
    """Return q, a scalar or (size,) array, finite and >= 0; ValueError otherwise."""
    try:
        q = np.array(process_noise, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError('process_noise must be a number or an array of shape '
                         f'({size},)') from exc
    if q.shape not in ((), (size,)):
        raise ValueError(f'process_noise must be a scalar or have shape ({size},), '
                         f'got {q.shape}')
    if not np.all(np.isfinite(q)) or np.any(q < 0):
        raise ValueError(f'process_noise must be finite and >= 0, got {process_noise!r}')
    return q


def _link_masks(measured, frames, p, m):
    """Return the links measured in each frame, (T, p, m) bool: all when ``measured`` is None."""
    if measured is None:
        return np.ones((frames, p, m), bool)
    masks = np.asarray(measured, dtype=bool)
    if masks.shape == (p, m):
        return np.broadcast_to(masks, (frames, p, m))
    if masks.shape != (frames, p, m):
        raise ValueError(f'measured must have shape ({p}, {m}) or ({frames}, {p}, {m}), '
                         f'got {masks.shape}')
    return masks
