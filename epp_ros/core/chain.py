"""Chain estimator: least squares over the boom's p + 1 angles (slew and one pitch each).

A pump boom has exactly p + 1 degrees of freedom, so both of the paper's features (fixed
lengths, one vertical plane) hold by construction. Levenberg–Marquardt with the analytic
Jacobian fits the ranges, warm-started from the previous frame; it is the maximum-likelihood
estimate under Gaussian range noise and attains the Cramér–Rao bound (``core.bounds``).

NLOS ranges are always too long. The loss is one-sided Huber: a range longer than predicted
by more than ``nlos_threshold`` sigma counts linearly, a shorter one quadratically. Links
still that long after the fit are reported per frame as NLOS and the posture is refit
without them, while the remaining links determine it.

Without a previous pose the global solution is found from several starts: the SR-LS per-tag
guess, and a grid of slews with the pitches chosen section by section; the best fit whose
joints are above the ground wins.
"""
import numpy as np

from .bounds import crlb
from .plane import fit_slew, to_plane

__all__ = ['ChainMethod', 'angles_from_joints', 'canonical_angles']


def angles_from_joints(model, joints):
    """Slew and pitches (radians) of the chain closest to the given joints (p, 3)."""
    slew = fit_slew(joints, model.base)
    coords = to_plane(np.vstack([model.base, joints]), model.base, slew)
    steps = np.diff(coords, axis=0)
    return slew, np.arctan2(steps[:, 1], steps[:, 0])


def canonical_angles(psi):
    """The same chain with its first section pointing outward, angles in [-pi, pi).

    ``(slew, pitch)`` and ``(slew + pi, pi - pitch)`` describe the same boom; the slew is
    the direction the first section points.
    """
    psi = np.array(psi, dtype=float)
    if np.cos(psi[1]) < 0:
        psi = np.r_[psi[0] + np.pi, np.pi - psi[1:]]
    return np.mod(psi + np.pi, 2 * np.pi) - np.pi


class ChainMethod:
    """Levenberg–Marquardt over (slew, pitch_1..pitch_p) on the measured ranges.

    Parameters
    ----------
    model : BoomModel
    sigma : float
        Range standard deviation, metres: scales the NLOS threshold and the predicted
        uncertainty (the estimate itself does not depend on it).
    nlos_threshold : float or None
        Excess, in sigmas, beyond which a too-long range counts linearly and is flagged;
        None for plain least squares.
    tol : float
        Stop when the step is below ``tol`` radians.
    max_iter : int
    slew_starts : int
        Slews tried by the cold start.
    """

    needs_prior = False         # the cold start finds the global solution by itself

    def __init__(self, model, sigma=0.1, nlos_threshold=3.0, tol=1e-10, max_iter=50,
                 slew_starts=16):
        self.model = model
        self.sigma = float(sigma)
        self.nlos_threshold = None if nlos_threshold is None else float(nlos_threshold)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.slew_starts = int(slew_starts)
        self._angles = None

    def enough_information(self, valid):
        """p + 1 unknowns; the tip's pitch is seen by the tip's ranges only."""
        return valid[-1].any() and valid.sum() >= self.model.n_sections + 1

    def reset(self):
        self._angles = None

    # -- the least-squares problem --------------------------------------------------------
    def _residuals(self, psi, ranges, valid):
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        offset = joints[:, None, :] - self.model.anchors[None, :, :]
        distance = np.linalg.norm(offset, axis=-1)
        return (distance - np.nan_to_num(ranges))[valid], offset, distance

    def _weights(self, residuals):
        """IRLS weights and robust cost of scaled residuals (one-sided Huber)."""
        scaled = residuals / self.sigma
        if self.nlos_threshold is None:
            return np.ones_like(scaled), 0.5 * np.sum(scaled ** 2)
        k = self.nlos_threshold
        long = scaled < -k                      # measured longer than predicted
        weights = np.where(long, k / np.maximum(-scaled, k), 1.0)
        cost = np.where(long, k * -scaled - 0.5 * k ** 2, 0.5 * scaled ** 2)
        return weights, float(np.sum(cost))

    def _jacobian(self, psi, offset, distance, valid):
        unit = offset / np.maximum(distance, 1e-12)[..., None]
        jacobian = np.einsum('kjc,kcq->kjq', unit,
                             self.model.joint_jacobian(psi[0], psi[1:]))
        return jacobian[valid] / self.sigma

    def fit(self, psi, ranges, valid):
        """Levenberg–Marquardt from ``psi``; returns (psi, cost, iterations)."""
        residuals, offset, distance = self._residuals(psi, ranges, valid)
        weights, cost = self._weights(residuals)
        damping = 1e-6
        for iteration in range(1, self.max_iter + 1):
            jacobian = self._jacobian(psi, offset, distance, valid)
            weighted = jacobian * weights[:, None]
            normal = weighted.T @ jacobian
            gradient = weighted.T @ (residuals / self.sigma)
            while True:
                step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9),
                                        gradient)
                trial = psi + step
                trial_residuals, trial_offset, trial_distance = self._residuals(
                    trial, ranges, valid)
                trial_weights, trial_cost = self._weights(trial_residuals)
                if trial_cost <= cost or damping > 1e10:
                    break
                damping *= 4.0
            if trial_cost > cost:
                return psi, cost, iteration
            stalled = cost - trial_cost <= 1e-12 * (1.0 + cost)
            psi, cost = trial, trial_cost
            residuals, offset, distance = trial_residuals, trial_offset, trial_distance
            weights = trial_weights
            damping = max(damping / 3.0, 1e-9)
            if stalled or np.max(np.abs(step)) <= self.tol:
                return psi, cost, iteration
        return psi, cost, self.max_iter

    def _flag(self, psi, ranges, valid):
        """Links measured longer than predicted by more than the NLOS threshold."""
        if self.nlos_threshold is None:
            return np.zeros_like(valid)
        predicted = self.model.ranges(self.model.forward_kinematics(psi[0], psi[1:]))
        with np.errstate(invalid='ignore'):
            return (ranges - predicted > self.nlos_threshold * self.sigma) & valid

    def _reject_nlos(self, psi, ranges, valid, rounds=3):
        """Refit without the flagged links until the flags settle.

        The Huber loss bounds an NLOS range's pull but does not remove it; a gross one can
        still push good links over the threshold. Links stay in the fit when removing them
        would leave the posture undetermined.
        """
        flagged = self._flag(psi, ranges, valid)
        iterations = 0
        for _ in range(rounds):
            if not flagged.any() or not self.enough_information(valid & ~flagged):
                break
            psi, _, used = self.fit(psi, ranges, valid & ~flagged)
            iterations += used
            again = self._flag(psi, ranges, valid)
            if np.array_equal(again, flagged):
                break
            flagged = again
        return psi, flagged, iterations

    # -- starts ---------------------------------------------------------------------------
    def _greedy_pitches(self, slew, ranges, valid, candidates=72):
        """Pitches chosen section by section to fit each tag's ranges, for a given slew."""
        grid = np.linspace(-np.pi, np.pi, candidates, endpoint=False)
        along = np.array([np.cos(slew), np.sin(slew), 0.0])
        steps = (np.cos(grid)[:, None] * along + np.sin(grid)[:, None] * [0.0, 0.0, 1.0])
        joint = self.model.base.copy()
        pitches = np.zeros(self.model.n_sections)
        for k, length in enumerate(self.model.arm_lengths):
            options = joint + length * steps
            if valid[k].any():
                distance = np.linalg.norm(options[:, None, :] - self.model.anchors[valid[k]],
                                          axis=-1)
                choice = np.argmin(np.sum((distance - ranges[k, valid[k]]) ** 2, axis=1))
            else:
                choice = np.argmin(np.abs(grid))      # unseen section: level
            pitches[k] = grid[choice]
            joint = options[choice]
        return pitches

    def _cold_starts(self, ranges, valid, guess):
        starts = []
        if guess is not None:
            slew, pitches = angles_from_joints(self.model, guess)
            starts.append(np.r_[slew, pitches])
        for slew in np.linspace(-np.pi, np.pi, self.slew_starts, endpoint=False):
            starts.append(np.r_[slew, self._greedy_pitches(slew, ranges, valid)])
        return starts

    def solve(self, ranges, prior):
        """Fit one frame. ``prior`` (p, 3) is used only when there is no previous fit."""
        valid = np.isfinite(ranges)
        fits = []
        total_iterations = 0
        if self._angles is not None:
            psi, cost, iterations = self.fit(self._angles, ranges, valid)
            fits.append((cost, psi))
            total_iterations += iterations
        # Cold start, or a warm start that lost track (worse than 5 sigma RMS per link).
        if self._angles is None or cost > 12.5 * valid.sum():
            # Every start is refined: with NLOS links the best-looking starts can all lie in
            # one wrong basin.
            for start in self._cold_starts(ranges, valid,
                                           prior if self._angles is None else None):
                psi, cost, iterations = self.fit(start, ranges, valid)
                fits.append((cost, psi))
                total_iterations += iterations
        above = [(c, psi) for c, psi in fits
                 if self.model.forward_kinematics(psi[0], psi[1:])[:, 2].min() >= -0.5]
        cost, psi = min(above or fits, key=lambda t: t[0])
        psi, nlos, iterations = self._reject_nlos(psi, ranges, valid)
        total_iterations += iterations
        psi = canonical_angles(psi)
        self._angles = psi
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        bound = crlb(self.model, psi[0], psi[1:], self.sigma, valid & ~nlos)
        info = {'iterations': total_iterations, 'converged': True, 'slew': float(psi[0]),
                'pitches': psi[1:].copy(), 'nlos_links': nlos,
                'predicted_rmse': bound.rmse, 'joint_std': bound.joint_std}
        return joints, info
