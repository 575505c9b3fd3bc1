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
Tracking estimator: the boom as a moving chain, its p + 1 angles and their rates.

A pump boom moves smoothly between joystick commands, so the last frames say much about
this one. The state ``x = (psi, psi_dot)`` follows a constant-velocity model with white
angular acceleration of spectral density ``q`` per angle (``core.bounds.posterior_crlb``
gives the limit it sets). Each frame is a maximum a posteriori fit of the state to the
prediction and to the frame: the chain's robust loss on the ranges (NLOS mixture), tag-tag
ranges, inclinometers and slew encoder, each range at the time it was measured (a tag ranges
in its own TDMA slot, ``delays`` seconds from the frame's stamp, when the boom was at
``psi + delay psi_dot``). This is an iterated extended Kalman filter with a robust loss.

- Process noise adapts: each angle's ``q`` follows how far the fits correct the prediction
  against how far they should (covariance matching), and a frame the prediction cannot
  explain (a joystick start, stop or reversal) is refitted with the rates let free.
- A tag that falls silent is predicted through, its growing uncertainty reported
  (``posterior_joint_std``). The integrity checks still judge each frame by its own
  measurements: a prediction, whose process noise is itself a guess, never makes a
  posture valid.
- Folds (a joint with too few ranges fits two ways) are kept as hypotheses, each its own
  filter weighted by how well it explains the frames, until the data decides.

A start, or a fit lost, goes back to the chain's global search (``core.chain``).
"""
from dataclasses import dataclass, replace

from epp_ros.core.estimation.methods.chain import angles_from_joints, canonical_angles, \
    ChainMethod, judged_minimum
from epp_ros.core.model.measurements import wrap_angle
from epp_ros.core.solvers.levenberg_marquardt import levenberg_marquardt, \
    LevenbergMarquardtResult, STALL
import numpy as np
from scipy.stats import chi2

#: Largest size of a correction in its standard deviations that the adaptation counts.
LARGEST_SCALED = np.sqrt(10.0)

__all__ = ['TrackMethod', 'Hypothesis', 'constant_velocity']


def constant_velocity(n, elapsed, process_noise):
    """
    Transition and process covariance of ``n`` angles and their rates over ``elapsed`` s.

    Returns
    -------
    transition : ndarray, shape (2 n, 2 n)
    covariance : ndarray, shape (2 n, 2 n)
        White angular acceleration of spectral density ``process_noise`` (scalar or (n,),
        rad^2/s^3).

    """
    q = np.broadcast_to(np.asarray(process_noise, dtype=float), (n,))
    eye = np.eye(n)
    transition = np.block([[eye, elapsed * eye], [np.zeros((n, n)), eye]])
    covariance = np.block([[np.diag(q * elapsed ** 3 / 3), np.diag(q * elapsed ** 2 / 2)],
                           [np.diag(q * elapsed ** 2 / 2), np.diag(q * elapsed)]])
    return transition, covariance


@dataclass
class Hypothesis:
    """One filter of the bank: its state, covariance and log weight."""

    state: np.ndarray           #: (2 (p + 1),) angles (rad) then rates (rad/s)
    covariance: np.ndarray      #: (2 (p + 1), 2 (p + 1))
    log_weight: float = 0.0     #: log of its relative probability
    #: Parameters its last frame's measurements determined (the rest came from the
    #: prediction): what the fit's residuals lost to it.
    fitted_dof: float = 0.0


class TrackMethod:
    """
    Robust iterated EKF over the boom's angles and rates, with a bank of fold hypotheses.

    Parameters
    ----------
    model : BoomModel
    process_noise : float
        Starting spectral density of each angle's acceleration, rad^2/s^3.
    adapt_process_noise : bool
        Adapt each angle's process noise to the corrections the fits make.
    max_rate : float
        Standard deviation of the rates at a start, rad/s.
    max_hypotheses : int
        Folds kept at once.
    ambiguity_odds : float
        A fold less likely than the best by more than this is dropped.
    manoeuvre_false_alarm : float
        Probability that a frame that follows the motion model is refitted as a manoeuvre.
    **chain_options
        For the chain estimator behind the searches and the loss: ``sigma``, ``eta``,
        ``tag_sigma``, ``pitch_sigma``, ``slew_sigma``, ``nlos_fraction``, ``nlos_gamma``,
        ``lowest_joint``, ``tol``, ``max_iter``, ``slew_starts``, ``screen_iterations``,
        ``search_budget``, ``link_bias_std``.

    """

    prior = 'optional'
    holds_chain = True
    inputs = ('ranges', 'tag_ranges', 'pitches', 'slew', 'range_stamps')
    delegates = (ChainMethod,)      # takes the chain's options too
    #: Process noise bounds, rad^2/s^3, and how fast it adapts (frames).
    PROCESS_NOISE_RANGE = (1e-7, 1.0)
    ADAPTATION_FRAMES = 50.0
    #: Lag-one correlation of successive corrections (over as many frames) above which
    #: corrections smaller than expected lower no process noise: the ranges' errors persist
    #: from frame to frame (real links' noise on a moving body), not the boom steadier.
    PERSISTENT_CORRECTIONS = 0.3
    #: Process noise of a manoeuvre, rad^2/s^3: the rates are free.
    MANOEUVRE_NOISE = 10.0
    #: A gap after which the rates are forgotten, s.
    LONGEST_COAST = 5.0
    #: Hypotheses closer than this in every angle are one, rad.
    SAME_FOLD = 0.05
    #: A fold's fit stops when a step lowers its cost by at most this fraction of it: its
    #: cost decides its place in the bank (against log ambiguity_odds), later frames its
    #: angles; on a frame nothing explains, settling further cost most of a start.
    FOLD_STALL = 1e-4
    #: Solves since the last :meth:`accept` whose state it can still commit.
    SOLVES_KEPT = 8

    def __init__(self, model, process_noise=1e-4, adapt_process_noise=True, max_rate=0.35,
                 max_hypotheses=4, ambiguity_odds=1000.0, manoeuvre_false_alarm=1e-3,
                 **chain_options):
        self.model = model
        self.chain = ChainMethod(model, **chain_options)
        n = model.n_sections + 1
        self.process_noise = np.full(n, _positive('process_noise', process_noise))
        self.initial_process_noise = self.process_noise.copy()
        self.adapt_process_noise = bool(adapt_process_noise)
        self._corrections = None        # the last scaled correction, running means
        self.max_rate = _positive('max_rate', max_rate)
        self.max_hypotheses = int(max_hypotheses)
        self.ambiguity_odds = _positive('ambiguity_odds', ambiguity_odds)
        self._manoeuvre_limit = chi2.isf(_positive('manoeuvre_false_alarm',
                                                   manoeuvre_false_alarm), n)
        self._bank = []                 # committed hypotheses, best first
        self._stamp = None              # of the committed state
        self._pending = []              # (info, state) of the solves since the last accept

    def tune(self, **noise):
        """Take new range noise values (see :meth:`ChainMethod.tune`)."""
        self.chain.tune(**noise)

    def reset(self, joints=None):
        """Forget the state; with ``joints`` (p, 3), start from that posture at rest."""
        self.chain.reset()
        self._bank, self._stamp, self._pending = [], None, []
        self.process_noise = self.initial_process_noise.copy()
        self._corrections = None
        if joints is not None:
            slew, pitches = angles_from_joints(self.model, np.asarray(joints, dtype=float))
            n = self.model.n_sections + 1
            covariance = np.diag(np.r_[np.full(n, 1e-2), np.full(n, self.max_rate ** 2)])
            self._bank = [Hypothesis(np.r_[slew, pitches, np.zeros(n)], covariance, 0.0,
                                     float(n))]

    @property
    def tracking(self):
        """Return whether a state is held."""
        return bool(self._bank)

    def enough_information(self, measurements):
        """
        Judge whether the frame can be used: any measurement while tracking.

        A frame with a silent tag still corrects the others; the prediction carries it.
        """
        if self.tracking and self._stamp is not None:
            return measurements.count() > 0
        return self.chain.enough_information(measurements)

    # -- the filter ------------------------------------------------------------------------
    def solve(self, measurements, prior, warm=False):
        """
        Fit one frame; :meth:`accept` commits it as the state.

        Warm and tracking: every hypothesis is predicted to the frame's stamp and fitted.
        Otherwise the chain's global search starts the bank afresh.
        """
        stamp = measurements.stamp
        delays = measurements.delays()
        if warm and self.tracking and self._stamp is not None and np.isfinite(stamp):
            bank, info = self._track(measurements, stamp, delays)
        else:
            bank, info = self._start(measurements, prior, warm)
        best = bank[0]
        n = self.model.n_sections + 1
        psi = canonical_angles(best.state[:n], self.model.pivot_offset)
        # (slew + pi, pi - pitches) is the same boom: the pitch rates turn with it.
        turned = np.r_[1.0, np.full(n - 1, -1.0 if np.cos(best.state[1]) < 0 and
                                    self.model.pivot_offset == 0.0 else 1.0)]
        joints = self.model.forward_kinematics(psi[0], psi[1:])
        postures = best.state[:n] + delays[:, None] * best.state[n:]
        timed = self.model.forward_kinematics(postures[:, 0], postures[:, 1:])
        others = [self.model.forward_kinematics(h.state[0], h.state[1:n]) for h in bank[1:]]
        info.update(slew=float(psi[0]), pitches=psi[1:].copy(),
                    rates=turned * best.state[n:], hypotheses=len(bank), rivals=others,
                    posterior_joint_std=self._joint_std(best),
                    fitted_dof=best.fitted_dof,
                    timed_joints=timed[np.arange(n - 1), np.arange(n - 1)])
        adaptation = info.pop('adaptation', (self.process_noise, self._corrections))
        # A frame can be solved more than once (a search beside the warm fit): each kept.
        state = (bank, stamp, adaptation)
        self._pending = (self._pending + [(info, state)])[-self.SOLVES_KEPT:]
        return joints, info

    def accept(self, info=None):
        """
        Commit the :meth:`solve` that returned ``info`` as the state (its fit was kept).

        Of the solves since the last accept (``SOLVES_KEPT`` at most), the one whose fit
        the frame kept (None: the last); the rest are forgotten. An ``info`` no kept solve
        returned commits nothing.
        """
        kept = [state for returned, state in self._pending if info is None or returned is info]
        if kept:
            self._bank, stamp, (self.process_noise, self._corrections) = kept[-1]
            self._stamp = stamp if np.isfinite(stamp) else None
        self._pending = []

    def _start(self, measurements, prior, warm):
        """
        Start the bank from the chain's fit: it, and its folds that fit about as well.

        Each inner joint folded and the tip at its other fitting pitches are fitted to the
        end: a joint with too few ranges keeps both ways until later frames decide.
        """
        joints, info = self.chain.solve(measurements, prior, warm=warm)
        n = self.model.n_sections + 1
        residuals = self.chain.residuals_of(measurements)
        best = np.r_[info['slew'], info['pitches']]
        fits = [(self.chain.cost(best, residuals), best)]
        range_sigma = np.broadcast_to(residuals.link_sigma(), measurements.ranges.shape)
        for start in (self.chain.folds(best)
                      + self.chain.tip_alternatives(best, measurements, range_sigma)):
            fit = self.chain.fit(start, residuals, stall=self.FOLD_STALL)
            fits.append((fit.cost, fit.psi))
        bank = []
        fits.sort(key=lambda fit: fit[0])
        for cost, psi in fits:
            log_weight = fits[0][0] - cost
            if log_weight < -np.log(self.ambiguity_odds) or len(bank) >= self.max_hypotheses:
                break
            if any(np.max(np.abs(wrap_angle(psi - h.state[:n]))) < self.SAME_FOLD
                   for h in bank):
                continue
            covariance = self._start_covariance(psi, residuals)
            bank.append(Hypothesis(np.r_[psi, np.zeros(n)], covariance, log_weight, float(n)))
        info = {'iterations': info['iterations'], 'converged': info['converged'],
                'searched': info.get('searched', True), 'manoeuvre': False,
                'alternatives': info.get('alternatives', [])}
        return bank, info

    def _start_covariance(self, psi, residuals):
        """Angles from the fit's information (regularised), rates up to ``max_rate``."""
        n = psi.size
        jacobian = residuals.jacobian(psi)
        information = jacobian.T @ jacobian + np.eye(n) * 1e-2     # at most ~10 rad std
        return np.block([[np.linalg.inv(information), np.zeros((n, n))],
                         [np.zeros((n, n)), np.eye(n) * self.max_rate ** 2]])

    def _track(self, measurements, stamp, delays):
        """Predict every hypothesis to ``stamp`` and fit it; the bank, best first, and info."""
        elapsed = max(stamp - self._stamp, 0.0)
        residuals = self.chain.residuals_of(measurements)
        bank, iterations, manoeuvre, converged = [], 0, False, True
        adaptation = (self.process_noise, self._corrections)
        for hypothesis in self._bank:
            predicted = self._predict(hypothesis, elapsed, self.process_noise)
            fitted, used, done, surprise = self._update(predicted, residuals, delays)
            iterations += used
            if surprise > self._manoeuvre_limit:    # the model did not hold: rates set free
                free = self._predict(hypothesis, elapsed, self.MANOEUVRE_NOISE)
                refit, used, refit_done, _ = self._update(free, residuals, delays)
                iterations += used
                if refit.log_weight > fitted.log_weight:
                    fitted, done, manoeuvre = refit, refit_done, True
            converged &= done
            if self.adapt_process_noise and hypothesis is self._bank[0]:
                adaptation = self._adapted(predicted, fitted, elapsed)
            bank.append(fitted)
        bank = self._prune(bank)
        return bank, {'iterations': iterations, 'converged': converged, 'searched': False,
                      'manoeuvre': manoeuvre, 'adaptation': adaptation}

    def _predict(self, hypothesis, elapsed, process_noise):
        n = self.model.n_sections + 1
        if elapsed > self.LONGEST_COAST:        # the rates of long ago say nothing
            covariance = hypothesis.covariance.copy()
            covariance[n:, :] = covariance[:, n:] = 0.0
            covariance[n:, n:] = np.eye(n) * self.max_rate ** 2
            hypothesis = Hypothesis(np.r_[hypothesis.state[:n], np.zeros(n)], covariance,
                                    hypothesis.log_weight)
        transition, noise = constant_velocity(n, elapsed, process_noise)
        return Hypothesis(transition @ hypothesis.state,
                          transition @ hypothesis.covariance @ transition.T + noise,
                          hypothesis.log_weight)

    def _update(self, predicted, residuals, delays, max_iter=None):
        """
        MAP fit of the state to the prediction and the frame (Levenberg–Marquardt).

        Returns the posterior hypothesis (its weight lowered by the fit's cost, a Laplace
        approximation of the frame's likelihood), the iterations, whether it converged, and
        the normalised size of the correction (chi-square with p + 1 degrees of freedom
        when the model holds).
        """
        prior_information = _inverse(predicted.covariance)

        chain, compiled = self.chain, self.chain.compiled()
        motion = (np.asarray(delays, dtype=float), predicted.state, prior_information)

        def evaluate(x, judged=False):
            return self._evaluate(x, predicted, prior_information, residuals, delays, judged)

        def judged_cost(x):
            if compiled is not None:
                return compiled.cost(x, self.model, residuals, compiled.loss_terms(
                    chain.losses(residuals)[True]), chain.lowest_joint, chain.GROUND_SIGMA,
                    motion)
            return evaluate(x, True)[0]

        def minimise(start, judged):
            """Fit from ``start``: its state the scaled residuals and the normal matrix."""
            iterations = chain.max_iter if max_iter is None else max_iter
            if compiled is not None:
                return LevenbergMarquardtResult(*compiled.fit(
                    start, self.model, residuals,
                    compiled.loss_terms(chain.losses(residuals)[judged]), chain.lowest_joint,
                    chain.GROUND_SIGMA, iterations, chain.tol, STALL, motion=motion))
            result = levenberg_marquardt(
                start, lambda x: evaluate(x, judged),
                lambda x, parts: self._normal_equations(x, predicted, prior_information,
                                                        *parts),
                max_iter=iterations, tol=chain.tol)
            normal, _ = self._normal_equations(result.x, predicted, prior_information,
                                               *result.state)
            return replace(result, state=(result.state[2][3], normal))

        n = residuals.n_ranged
        # Under the judge's loss, as the chain's fits: one short range is let go.
        fit = judged_minimum(minimise, chain.losses(residuals),
                             lambda result: result.state[0][:n],
                             judged_cost, predicted.state.copy(),
                             refit=max_iter is None)
        state, cost, iterations, converged = fit.x, fit.cost, fit.iterations, fit.converged
        covariance = _inverse(fit.state[1])
        n = self.model.n_sections + 1
        correction = state - predicted.state
        # Laplace: -log p(frame) ~ cost + 0.5 log det(P_prior / P_posterior).
        _, log_det_prior = np.linalg.slogdet(predicted.covariance)
        _, log_det_post = np.linalg.slogdet(covariance)
        log_weight = predicted.log_weight - cost - 0.5 * (log_det_prior - log_det_post)
        # The correction's own covariance is P_prior - P_posterior.
        spread = predicted.covariance - covariance
        surprise = float(correction[:n] @ _pseudo_solve(spread[:n, :n], correction[:n]))
        fitted_dof = float(2 * n - np.trace(covariance @ prior_information))
        return (Hypothesis(state, covariance, log_weight, fitted_dof), iterations, converged,
                surprise)

    def _evaluate(self, state, predicted, prior_information, residuals, delays, judged=False):
        """Cost of a state: prediction term, robust loss (``judged``: the judge's), ground."""
        n = self.model.n_sections + 1
        scaled, jacobian, joints = residuals.timed(state[:n], state[n:], delays)
        cost, slope, weights, _ = self.chain.loss(scaled, residuals, judged)
        difference = state - predicted.state
        difference[:n] = wrap_angle(difference[:n])
        cost += 0.5 * float(difference @ prior_information @ difference)
        depth = np.maximum(self.chain.lowest_joint - joints[:, 2], 0.0) / self.chain.GROUND_SIGMA
        cost += 0.5 * float(depth @ depth)
        return cost, (slope, weights, (jacobian, difference, depth, scaled))

    def _normal_equations(self, state, predicted, prior_information, slope, weights, rows):
        jacobian, difference, depth, _ = rows
        normal = prior_information + (jacobian * weights[:, None]).T @ jacobian
        gradient = prior_information @ difference + jacobian.T @ slope
        if depth.any():
            n = self.model.n_sections + 1
            sinking = np.zeros((self.model.n_sections, 2 * n))
            sinking[:, :n] = -self.model.joint_jacobian(state[0], state[1:n])[:, 2, :]
            sinking = sinking[depth > 0] / self.chain.GROUND_SIGMA
            normal = normal + sinking.T @ sinking
            gradient = gradient + sinking.T @ depth[depth > 0]
        return normal, gradient

    def _adapted(self, predicted, fitted, elapsed):
        """
        Return each angle's process noise moved toward what its correction says.

        A correction of angle i has variance ``P_prior,ii - P_post,ii`` when the model holds
        (covariance matching); corrections larger on average mean the boom accelerates
        more than ``q`` allows. That assumes each frame's range errors new: where successive
        corrections are correlated (:data:`PERSISTENT_CORRECTIONS`) the prediction carries
        the last frame's errors into this one and the corrections seem small, so ``q`` is
        then only raised. Also the corrections' memory; both committed with the frame, by
        :meth:`accept`.
        """
        if elapsed <= 0.0:
            return self.process_noise, self._corrections
        n = self.model.n_sections + 1
        correction = wrap_angle(fitted.state[:n] - predicted.state[:n])
        expected = np.diag(predicted.covariance - fitted.covariance)[:n]
        scaled = np.clip(correction / np.sqrt(np.maximum(expected, 1e-18)), -LARGEST_SCALED,
                         LARGEST_SCALED)
        # Stochastic approximation of E[scaled^2] = 1 (a mean: a log would settle low).
        step = 1.0 + (scaled ** 2 - 1.0) / self.ADAPTATION_FRAMES
        corrections = self._remembered(scaled)
        _, product, square = corrections
        step = np.where(product > self.PERSISTENT_CORRECTIONS * square, np.maximum(step, 1.0),
                        step)
        return np.clip(self.process_noise * step, *self.PROCESS_NOISE_RANGE), corrections

    def _remembered(self, scaled):
        """Return ``scaled`` and the running means of successive corrections' products, squares."""
        if self._corrections is None:
            return scaled, np.zeros_like(scaled), scaled ** 2
        last, product, square = self._corrections
        weight = 1.0 / self.ADAPTATION_FRAMES
        return (scaled, product + weight * (scaled * last - product),
                square + weight * (scaled ** 2 - square))

    def _prune(self, bank):
        """Best first; folds far less likely dropped, those that met merged."""
        bank = sorted(bank, key=lambda h: -h.log_weight)
        n = self.model.n_sections + 1
        kept = []
        for hypothesis in bank:
            if hypothesis.log_weight < bank[0].log_weight - np.log(self.ambiguity_odds):
                break
            if any(np.max(np.abs(wrap_angle(hypothesis.state[:n] - h.state[:n])))
                   < self.SAME_FOLD for h in kept):
                continue
            kept.append(hypothesis)
        best = kept[0].log_weight
        for hypothesis in kept:             # keep the numbers small
            hypothesis.log_weight -= best
        return kept[:self.max_hypotheses]

    def _joint_std(self, hypothesis):
        """Return each joint's posterior standard deviation (p,), metres."""
        n = self.model.n_sections + 1
        psi = hypothesis.state[:n]
        jacobian = self.model.joint_jacobian(psi[0], psi[1:])
        covariance = np.einsum('kcq,qr,kcr->k', jacobian, hypothesis.covariance[:n, :n],
                               jacobian)
        return np.sqrt(np.maximum(covariance, 0.0))


def _positive(name, value):
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f'{name}: must be a finite number > 0, got {value!r}')
    return value


def _inverse(matrix):
    """Inverse of a symmetric positive definite matrix, symmetrised."""
    inverse = np.linalg.inv(matrix)
    return 0.5 * (inverse + inverse.T)


def _pseudo_solve(matrix, vector):
    """Solve ``matrix x = vector`` for a symmetric positive semi-definite matrix."""
    values, vectors = np.linalg.eigh(matrix)
    keep = values > 1e-12 * max(values[-1], 1e-300)
    return vectors[:, keep] @ ((vectors[:, keep].T @ vector) / values[keep])
