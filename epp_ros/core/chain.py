"""Chain estimator: least squares over the boom's p + 1 angles (slew and one pitch each).

A pump boom has exactly p + 1 degrees of freedom, so both of the paper's features (fixed
lengths, one vertical plane) hold by construction. Levenberg–Marquardt with the analytic
Jacobian fits the ranges, warm-started from the previous frame; it is the maximum-likelihood
estimate under Gaussian range noise and attains the Cramér–Rao bound (``core.bounds``).

NLOS ranges are always too long. The loss is one-sided Huber: a range longer than predicted
by more than ``nlos_threshold`` sigma counts linearly, a shorter one quadratically. Links
still that long after the fit are reported per frame as NLOS and the posture is refit
without them, while the remaining links determine it.

Tag-tag ranges, inclinometers and a slew encoder, when given, enter the same least squares
with their own sigmas (``core.measurements``), so the paper's TPSM angles add information
instead of being discarded.

Without a previous pose the global solution is found from several starts: the SR-LS per-tag
guess, and a grid of slews with the pitches chosen section by section; the best fit whose
joints are above the ground wins.
"""
from dataclasses import replace

import numpy as np

from .bounds import bound_from_information
from .measurements import Residuals, SensorNoise, wrap_angle
from .plane import fit_slew, to_plane

__all__ = ['ChainMethod', 'angles_from_joints', 'canonical_angles']


def angles_from_joints(model, joints):
    """Slew and pitches (radians) of the chain closest to the given joints (p, 3)."""
    slew = fit_slew(joints, model.base)
    coords = to_plane(np.vstack([model.pivot(slew), joints]), model.base, slew)
    steps = np.diff(coords, axis=0)
    return slew, np.arctan2(steps[:, 1], steps[:, 0])


def canonical_angles(psi, pivot_offset=0.0):
    """The same chain with its first section pointing outward, angles in [-pi, pi).

    With the pivot on the slew axis, ``(slew, pitch)`` and ``(slew + pi, pi - pitch)``
    describe the same boom; the slew is the direction the first section points. A pivot
    off the axis tells them apart, and only the wrapping applies.
    """
    psi = np.array(psi, dtype=float)
    if pivot_offset == 0.0 and np.cos(psi[1]) < 0:
        psi = np.r_[psi[0] + np.pi, np.pi - psi[1:]]
    return wrap_angle(psi)


class ChainMethod:
    """Levenberg–Marquardt over (slew, pitch_1..pitch_p) on everything measured.

    Parameters
    ----------
    model : BoomModel
    sigma : float
        Tag-anchor range standard deviation, metres: weighs the ranges against the other
        sensors, scales the NLOS threshold and the predicted uncertainty.
    eta : float
        Multiplicative range noise factor (the paper's): a range r has standard deviation
        ``sqrt(sigma^2 + (eta r)^2)``.
    tag_sigma : float or None
        Tag-tag range standard deviation, metres (None: ``sigma``).
    pitch_sigma, slew_sigma : float
        Inclinometer and slew encoder standard deviations, radians.
    nlos_threshold : float or None
        Excess, in sigmas, beyond which a too-long range counts linearly and is flagged;
        None for plain least squares.
    tol : float
        Stop when the step is below ``tol`` radians.
    max_iter : int
    slew_starts : int
        Slews tried by the cold start.
    """

    prior = 'optional'          # one more start; the cold start finds the global solution
    inputs = ('ranges', 'tag_ranges', 'pitches', 'slew')

    def __init__(self, model, sigma=0.1, eta=0.0, tag_sigma=None, pitch_sigma=np.radians(0.5),
                 slew_sigma=np.radians(0.5), nlos_threshold=3.0, tol=1e-10, max_iter=50,
                 slew_starts=16):
        self.model = model
        self.eta = float(eta)
        self.noise = SensorNoise(float(sigma), float(sigma if tag_sigma is None else tag_sigma),
                                 float(pitch_sigma), float(slew_sigma))
        self.nlos_threshold = None if nlos_threshold is None else float(nlos_threshold)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.slew_starts = int(slew_starts)
        self._angles = None

    def enough_information(self, measurements):
        """p + 1 unknowns; the tip's pitch is seen only by the tip's ranges or inclinometer."""
        tip_seen = (np.isfinite(measurements.ranges[-1]).any()
                    or np.isfinite(measurements.tag_ranges[-1]).any()
                    or np.isfinite(measurements.tag_ranges[:, -1]).any()
                    or np.isfinite(measurements.pitches[-1]))
        return bool(tip_seen) and measurements.count() >= self.model.n_sections + 1

    def reset(self):
        self._angles = None

    # -- the least-squares problem --------------------------------------------------------
    def _loss(self, scaled, ranged):
        """IRLS weights and robust cost of scaled residuals (one-sided Huber on ranges)."""
        if self.nlos_threshold is None:
            return np.ones_like(scaled), 0.5 * float(scaled @ scaled)
        k = self.nlos_threshold
        long = ranged & (scaled > k)            # measured shorter than predicted: no
        weights = np.where(long, k / np.maximum(scaled, k), 1.0)
        cost = np.where(long, k * scaled - 0.5 * k ** 2, 0.5 * scaled ** 2)
        return weights, float(np.sum(cost))

    def fit(self, psi, residuals):
        """Levenberg–Marquardt from ``psi`` on a :class:`Residuals`; (psi, cost, iterations)."""
        ranged = residuals.ranged()
        scaled, geometry = residuals.residuals(psi)
        weights, cost = self._loss(-scaled, ranged)
        damping = 1e-6
        for iteration in range(1, self.max_iter + 1):
            jacobian = residuals.jacobian(psi, geometry)
            weighted = jacobian * weights[:, None]
            normal = weighted.T @ jacobian
            gradient = weighted.T @ scaled
            while True:
                step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9),
                                        gradient)
                trial = psi + step
                trial_scaled, trial_geometry = residuals.residuals(trial)
                trial_weights, trial_cost = self._loss(-trial_scaled, ranged)
                if trial_cost <= cost or damping > 1e10:
                    break
                damping *= 4.0
            if trial_cost > cost:
                return psi, cost, iteration
            stalled = cost - trial_cost <= 1e-12 * (1.0 + cost)
            psi, cost = trial, trial_cost
            scaled, geometry, weights = trial_scaled, trial_geometry, trial_weights
            damping = max(damping / 3.0, 1e-9)
            if stalled or np.max(np.abs(step)) <= self.tol:
                return psi, cost, iteration
        return psi, cost, self.max_iter

    def _flag(self, psi, residuals):
        """Ranges measured longer than predicted by more than the NLOS threshold (rows)."""
        if self.nlos_threshold is None:
            return np.zeros(residuals.size, bool)
        scaled, _ = residuals.residuals(psi)
        return residuals.ranged() & (-scaled > self.nlos_threshold)

    def _without(self, measurements, residuals, rows):
        links, tag_links = residuals.link_flags(rows)
        return measurements.with_ranges(np.where(links, np.nan, measurements.ranges),
                                        np.where(tag_links, np.nan, measurements.tag_ranges))

    def _reject_nlos(self, psi, measurements, residuals, rounds=3):
        """Refit without the flagged ranges until the flags settle.

        The Huber loss bounds an NLOS range's pull but does not remove it; a gross one can
        still push good links over the threshold. Links stay in the fit when removing them
        would leave the posture undetermined.
        """
        flagged = self._flag(psi, residuals)
        iterations = 0
        for _ in range(rounds):
            if not flagged.any():
                break
            kept = self._without(measurements, residuals, flagged)
            if not self.enough_information(kept):
                break
            psi, _, used = self.fit(psi, Residuals(self.model, kept, residuals.noise))
            iterations += used
            again = self._flag(psi, residuals)
            if np.array_equal(again, flagged):
                break
            flagged = again
        return psi, flagged, iterations

    # -- starts ---------------------------------------------------------------------------
    def _greedy_pitches(self, slew, measurements, candidates=72):
        """Pitches chosen section by section to fit each tag's ranges, for a given slew.

        A section with an inclinometer reading takes it.
        """
        ranges = measurements.ranges
        valid = np.isfinite(ranges)
        grid = np.linspace(-np.pi, np.pi, candidates, endpoint=False)
        along = np.array([np.cos(slew), np.sin(slew), 0.0])
        joint = self.model.pivot(slew)
        pitches = np.zeros(self.model.n_sections)
        for k, length in enumerate(self.model.arm_lengths):
            options = grid
            if np.isfinite(measurements.pitches[k]):
                options = measurements.pitches[k:k + 1]
            ends = joint + length * (np.cos(options)[:, None] * along
                                     + np.sin(options)[:, None] * [0.0, 0.0, 1.0])
            if valid[k].any() and options.size > 1:
                distance = np.linalg.norm(ends[:, None, :] - self.model.anchors[valid[k]],
                                          axis=-1)
                choice = np.argmin(np.sum((distance - ranges[k, valid[k]]) ** 2, axis=1))
            else:
                choice = np.argmin(np.abs(options))   # unseen section: level
            pitches[k] = options[choice]
            joint = ends[choice]
        return pitches

    def _cold_starts(self, measurements, guess):
        starts = []
        if guess is not None:
            slew, pitches = angles_from_joints(self.model, guess)
            starts.append(np.r_[slew, pitches])
        slews = np.linspace(-np.pi, np.pi, self.slew_starts, endpoint=False)
        if np.isfinite(measurements.slew):
            slews = np.r_[measurements.slew, slews]
        for slew in slews:
            starts.append(np.r_[slew, self._greedy_pitches(slew, measurements)])
        return starts

    def solve(self, measurements, prior):
        """Fit one frame. ``prior`` (p, 3) is used only when there is no previous fit."""
        noise = self.noise
        if self.eta:
            distances = np.nan_to_num(measurements.ranges)
            noise = replace(noise, range_sigma=np.hypot(noise.range_sigma, self.eta * distances))
        residuals = Residuals(self.model, measurements, noise)
        fits = []
        total_iterations = 0
        if self._angles is not None:
            psi, cost, iterations = self.fit(self._angles, residuals)
            fits.append((cost, psi))
            total_iterations += iterations
        # Cold start, or a warm start that lost track (worse than 5 sigma RMS per residual).
        if self._angles is None or cost > 12.5 * residuals.size:
            # Every start is refined: with NLOS links the best-looking starts can all lie in
            # one wrong basin.
            for start in self._cold_starts(measurements,
                                           prior if self._angles is None else None):
                psi, cost, iterations = self.fit(start, residuals)
                fits.append((cost, psi))
                total_iterations += iterations
        above = [(c, psi) for c, psi in fits
                 if self.model.forward_kinematics(psi[0], psi[1:])[:, 2].min() >= -0.5]
        cost, psi = min(above or fits, key=lambda t: t[0])
        psi, flagged, iterations = self._reject_nlos(psi, measurements, residuals)
        total_iterations += iterations
        psi = canonical_angles(psi, self.model.pivot_offset)
        self._angles = psi
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        nlos, nlos_tags = residuals.link_flags(flagged)
        kept_rows = residuals.jacobian(psi)[~flagged]       # the links that determine psi
        bound = bound_from_information(self.model, psi[0], psi[1:], kept_rows.T @ kept_rows)
        info = {'iterations': total_iterations, 'converged': True, 'slew': float(psi[0]),
                'pitches': psi[1:].copy(), 'nlos_links': nlos, 'nlos_tag_links': nlos_tags,
                'predicted_rmse': bound.rmse, 'joint_std': bound.joint_std}
        return joints, info
