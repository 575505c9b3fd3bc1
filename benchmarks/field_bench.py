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
``python3 dev.py bench field``: the estimators with their defaults on the field's effects.

Each case is a field effect of ``core.simulate`` (alone, or all that need no calibration
together) on the simulated truck pump at 10 Hz, the estimators told only the defaults
(sigma 0.1 m, NLOS fraction 0.1, mean excess 1 m). Scored against the truth at each frame's
stamp, after a warm-up, as RMSE over the clean line-of-sight Cramér–Rao bound at the true
noise (every link measured, none blocked; ``sigma0 + k r`` per link):

- ``chain``, ``cepp``, ``track``: the defaults; ``chain told``: told the true sigma (and
  NLOS model) and learning nothing, the column the learned noise is measured against;
- ``track`` also over the posterior bound of its motion model, on a case where that model
  holds (``cv``: angles whose rates are random walks of the tracker's process noise);
- the authors' geometry (xie3dim) at sigma 1 and 2 m, every frame from a cold start and a
  new estimator;
- cost: track and chain per frame, and the chain's Gauss-Newton against scipy's
  ``least_squares`` on the same fits.

Offsets and moved anchors are calibration's (no target here): they must not diverge. The
moved anchors are the outriggers (``simulate.truck_outriggers``): the turret's and the cab's
define the truck frame and stay.

``python3 dev.py bench family`` runs the same scoring on the ``real_uwb`` preset varied
(:data:`FAMILY`): real links differ by site, device and mounting, and what the package
publishes must hold on the family, not on the preset's figures alone.
"""
from dataclasses import dataclass, replace
import time

from epp_ros.core import PostureEstimator
from epp_ros.core.estimation import IntegrityLimits, wrong_frames
from epp_ros.core.estimation.methods import angles_from_joints, ChainMethod
from epp_ros.core.model import crlb, posterior_crlb
from epp_ros.core.model import Measurements, Residuals, SensorNoise
from epp_ros.core.simulation import (BOOM_52M, FIELD_EFFECTS, field_effects, FieldEffects,
                                     JoystickMotion, Motion, simulate_field, truck_outriggers,
                                     truck_pump, WorkingMotion, xie3dim)
import numpy as np
from scipy.optimize import least_squares

__all__ = ['CASES', 'case_frames', 'FAMILY', 'FamilyReport', 'FieldReport', 'run', 'run_family']

RATE = 10.0                     #: frames per second
WARM_UP_S = 5.0                 #: seconds not scored: a cold start, the noise being learned
METHODS = ('chain', 'cepp', 'track', 'chain told')
#: name: (effects, motion, target of chain, cepp, track (vs the single-frame bound)).
CASES = {
    'clean': ('', 'working'),
    'sigma_high': ('sigma_high', 'working'),
    'sigma_low': ('sigma_low', 'working'),
    'sigma_distance': ('sigma_distance', 'working'),
    'nlos_persistent': ('nlos_persistent', 'working'),
    'tdma': ('tdma', 'working'),
    'dropouts': ('dropouts', 'working'),
    'joystick': ('', 'joystick'),
    'all': ('sigma_distance,nlos_persistent,tdma,dropouts', 'working'),
    'offsets': ('offsets', 'working'),
    'anchors_moved': ('anchors_moved', 'working'),
    'real_uwb': ('real_uwb', 'working'),
}
CALIBRATION = ('offsets', 'anchors_moved', 'real_uwb')
TARGETS = {'chain': 1.15, 'cepp': 1.3, 'track': 0.7}


def _real_uwb_family():
    """Return :data:`FAMILY`: the ``real_uwb`` preset with one thing changed in each."""
    real = FIELD_EFFECTS['real_uwb']
    curve_doubled = tuple((distance, 2.0 * bias) for distance, bias in real.bias_curve)
    slow = {'correlated_fraction': 0.9, 'noise_correlation_time': 6.0}
    return {
        'pair terms x2': (replace(real, link_offset=2.0 * real.link_offset), 'working'),
        'range curve x2': (replace(real, bias_curve=curve_doubled), 'working'),
        'orientation x2': (replace(real, orientation_bias=2.0 * real.orientation_bias),
                           'working'),
        'slow noise': (replace(real, **slow), 'working'),
        'outliers x10, 3 m': (replace(real, outlier_rate=10.0 * real.outlier_rate,
                                      outlier_size=3.0), 'working'),
        'outliers x100, 3 m': (replace(real, outlier_rate=100.0 * real.outlier_rate,
                                       outlier_size=3.0), 'working'),
        'devices 0.15 m': (replace(real, tag_offset=0.15, anchor_offset=0.15, range_bias=0.0),
                           'working'),
        'all x2': (replace(real, sigma=0.1, link_offset=2.0 * real.link_offset,
                           bias_curve=curve_doubled,
                           orientation_bias=2.0 * real.orientation_bias, **slow), 'working'),
        '+ nlos_persistent': ('real_uwb,nlos_persistent', 'working'),
        '+ dropouts': ('real_uwb,dropouts', 'working'),
        '+ tdma': ('real_uwb,tdma', 'working'),
        '+ all four': ('real_uwb,nlos_persistent,tdma,dropouts', 'working'),
        'on joystick': ('real_uwb', 'joystick'),
        # Other pumps (``truck_pump``'s keywords): where a warm fit drifted with what it
        # published and searches found the truth beyond its reach (docs/benchmarks.md).
        '+ tdma, four anchors, joystick': ('real_uwb,tdma', 'joystick', {'n_anchors': 4}),
        '+ all four, 52 m boom, joystick': ('real_uwb,nlos_persistent,tdma,dropouts',
                                            'joystick', BOOM_52M),
    }


#: name: (effects, motion[, truck_pump's keywords]): the real links' preset varied as sites,
#: devices and mountings vary it (each real-link figure doubled; outliers ten and a hundred
#: times as often (a fifth of the ranges) and 3 m; device offsets of 0.15 m), with the
#: other field effects and the joystick, and on other pumps.
FAMILY = _real_uwb_family()
#: The process noise of the ``cv`` case, rad^2/s^3.
CV_PROCESS_NOISE = 1e-4


class RandomWalkMotion(Motion):
    """Angles whose rates are random walks (the tracker's motion model), sampled finely."""

    def __init__(self, model, duration, rng, process_noise, step=0.01):
        n = model.n_sections + 1
        self.model = model
        self.times = np.arange(0.0, duration + step, step)
        accelerations = rng.normal(0.0, np.sqrt(process_noise / step), (self.times.size, n))
        rates = np.cumsum(accelerations * step, axis=0)
        start = np.r_[0.3, np.radians(np.linspace(50.0, -40.0, n - 1))]
        self.psi = start + np.cumsum(rates * step, axis=0)

    def angles(self, times):
        psi = np.stack([np.interp(times, self.times, column) for column in self.psi.T], -1)
        return psi[..., 0], psi[..., 1:]


def _motion(name, model, seconds, rng):
    if name == 'joystick':
        return JoystickMotion(model, seconds, rng)
    if name == 'cv':
        return RandomWalkMotion(model, seconds, rng, CV_PROCESS_NOISE)
    return WorkingMotion(model, rng)


def _estimators(model, effects):
    told = {'sigma': effects.sigma, 'eta': effects.sigma_per_metre,
            'nlos_fraction': max(effects.nlos_fraction, 1e-3),
            'nlos_gamma': effects.nlos_gamma}
    # The outriggers may stand elsewhere than configured, as on a pump set up again.
    moving = truck_outriggers(model)
    return {'chain': PostureEstimator(model, 'chain', moving_anchors=moving),
            'cepp': PostureEstimator(model, 'cepp', moving_anchors=moving),
            'track': PostureEstimator(model, 'track', moving_anchors=moving),
            'chain told': PostureEstimator(model, 'chain', learn_noise=False, **told)}


def _true_sigma(model, frame, effects):
    """Return each link's range std as the simulator draws it (p, m): ``sigma0 + k r``."""
    return effects.sigma + effects.sigma_per_metre * model.ranges(frame.joints)


def _clean_bound(model, frame, effects):
    """Return the clean line-of-sight bound (m) at the true posture and noise."""
    return crlb(model, frame.slew_true, frame.pitches_true,
                _true_sigma(model, frame, effects)).rmse


def truth_decides(model, frame, effects, ambiguous_joints):
    """
    Whether the frame's own ranges rule out every other fit of the joints called ambiguous.

    The information a frame holds, by an oracle that knows the truth: under the noise the
    simulator draws (``sigma0 + k r``, its NLOS fraction and excess; biases unknown, as to
    the estimator; the ranges alone), the chain is fitted from the true posture and from
    it with each flagged joint folded (an inner joint) or the tip at its other fitting
    pitches; each such posture, and its fit, that puts a joint more than
    ``ambiguity_distance`` away must be more than ``ambiguity_odds`` times less likely.
    ``ambiguous_joints``: 1-based, as in the diagnostics. False when a tag is silent (one
    frame cannot place its joint).
    """
    ranges = frame.inputs()['ranges']
    if not np.isfinite(ranges).any(axis=1).all():
        return False
    limits = IntegrityLimits()
    sigma = _true_sigma(model, frame, effects)
    measurements = Measurements.ranges_only(ranges)
    chain = ChainMethod(model, effects.sigma, nlos_fraction=effects.nlos_fraction,
                        nlos_gamma=effects.nlos_gamma)
    residuals = Residuals(model, measurements, SensorNoise(sigma))
    truth = chain.fit(np.r_[frame.slew_true, frame.pitches_true], residuals)
    folds, starts = chain.folds(truth.psi), []
    for k in np.asarray(ambiguous_joints, dtype=int) - 1:
        starts += ([folds[k]] if k < model.n_sections - 1
                   else chain.tip_alternatives(truth.psi, measurements, sigma))
    there = model.forward_kinematics(truth.psi[0], truth.psi[1:])
    for start in starts:
        # The fold itself is a posture; its fit may find a likelier one, or slide back.
        for psi, cost in ((start, chain.cost(start, residuals)),
                          chain.fit(start, residuals)[:2]):
            moved = np.linalg.norm(model.forward_kinematics(psi[0], psi[1:]) - there, axis=1)
            if moved.max() > limits.ambiguity_distance and \
                    cost - truth.cost < np.log(limits.ambiguity_odds):
                return False
    return True


def case_frames(name, seconds, seed):
    """
    Return the frames of case ``name`` (``CASES``, ``FAMILY`` or a motion), the pump, its effects.

    On the truck pump (or a family case's own) at ``RATE``; a list of ``FieldFrame``, the
    ``BoomModel`` as configured and the ``FieldEffects`` drawn.
    """
    spec, motion_name, *pump = CASES.get(name) or FAMILY.get(name) or ('', name)
    model = truck_pump(**(pump[0] if pump else {}))
    rng = np.random.default_rng([seed, sum(map(ord, name))])
    effects = spec if isinstance(spec, FieldEffects) else \
        field_effects(spec) if spec else FieldEffects()
    if effects.moving_anchors is None:      # the body's anchors stay on the body
        effects = replace(effects, moving_anchors=truck_outriggers(model))
    motion = _motion(motion_name, model, seconds, rng)
    return simulate_field(model, motion, seconds, effects, rng, 1.0 / RATE), model, effects


def run_case(name, seconds, seed):
    """Return per method (squared errors, valid count) and the bounds of one case."""
    frames, model, effects = case_frames(name, seconds, seed)
    scored = [frame.stamp >= WARM_UP_S for frame in frames]
    bounds = np.array([_clean_bound(model, f, effects) for f in frames])[scored]
    results = {}
    for method, estimator in _estimators(model, effects).items():
        squared, valid, times, published, predicted, decidable = [], 0, [], [], [], 0
        for frame, score in zip(frames, scored):
            start = time.perf_counter()
            returned = estimator.update(**frame.inputs())
            times.append(time.perf_counter() - start)
            diagnostics = estimator.last_diagnostics
            if score:           # the method's answer; the last valid one when it had none
                estimate = diagnostics.get('estimate', returned)
                error = np.mean(np.sum((estimate - frame.joints) ** 2, axis=1))
                squared.append(error)
                valid += diagnostics['valid']
                published.append(bool(diagnostics['valid']))
                predicted.append(diagnostics.get('predicted_rmse', np.nan))
                decidable += diagnostics['status'] == 'ambiguous' and truth_decides(
                    model, frame, effects, diagnostics['ambiguous_joints'])
        results[method] = {'squared': np.array(squared), 'valid': valid,
                           'published': np.array(published, dtype=bool),
                           'predicted': np.array(predicted, dtype=float),
                           'ms': 1e3 * float(np.median(times)), 'decidable': decidable}
    return results, bounds, frames, model


def _ratio(squared, bounds):
    return float(np.sqrt(np.mean(squared) / np.mean(bounds ** 2)))


def _case_runs(name, seconds, seeds):
    """
    Run a case once per seed.

    Returns
    -------
    bounds : ndarray
        The clean bound of each scored frame, metres, every run.
    heard : ndarray of bool
        Of those, the frames with every tag heard.
    runs : dict
        Per method, a list of :func:`run_case`'s results, one per run, each with its
        ``gross``: frames more than 5 bounds + 0.5 m off.

    """
    bounds, heard, runs = [], [], {method: [] for method in METHODS}
    for seed in range(seeds):
        results, case_bounds, frames, _ = run_case(name, seconds, seed)
        bounds.append(case_bounds)
        heard.append([not f.silent.any() for f in frames if f.stamp >= WARM_UP_S])
        for method in METHODS:
            squared = results[method]['squared']
            gross = int(np.sum(np.sqrt(squared) > 5 * case_bounds + 0.5))
            runs[method].append(dict(results[method], gross=gross))
    return np.concatenate(bounds), np.concatenate(heard), runs


def _ratio_over(squared, bounds, frames):
    """Return :func:`_ratio` over some frames (a boolean mask), NaN when there are none."""
    return _ratio(squared[frames], bounds[frames]) if frames.any() else float('nan')


def _method_cell(runs, bounds, heard):
    """Return a method's figures in a case from its runs (see :func:`_case_runs`)."""
    squared = np.concatenate([run['squared'] for run in runs])
    published = np.concatenate([run['published'] for run in runs])
    predicted = np.concatenate([run['predicted'] for run in runs])
    wrong, confident = wrong_frames(squared, published, predicted)
    decidable = sum(run['decidable'] for run in runs)
    return {'decidable': decidable,
            # of the frames the information allows: published, and refused the truth decides
            'allowed_share': published.sum() / max(published.sum() + decidable, 1),
            'ratio': _ratio(squared, bounds), 'heard_ratio': _ratio_over(squared, bounds, heard),
            'published_ratio': _ratio_over(squared, bounds, published),
            'valid': sum(run['valid'] for run in runs) / bounds.size,
            'gross': sum(run['gross'] for run in runs),
            'wrong_valid': wrong, 'confidently_wrong': confident}


def field_rows(seconds, seeds, names=tuple(CASES)):
    """Ratio to the clean bound per case (of :data:`CASES` or :data:`FAMILY`) and method."""
    rows = []
    for name in names:
        bounds, heard, runs = _case_runs(name, seconds, seeds)
        rows.append({'case': name, 'frames': int(bounds.size),
                     'bound_m': float(np.sqrt(np.mean(bounds ** 2))),
                     'heard': float(np.mean(heard)),
                     **{method: _method_cell(runs[method], bounds, heard)
                        for method in METHODS}})
    return rows


def posterior_row(seconds, seeds):
    """Track on angles that follow its motion model, over the posterior and frame bounds."""
    squared, posterior, single = [], [], []
    for seed in range(seeds):
        results, bounds, frames, model = run_case('cv', seconds, seed)
        slew = np.array([f.slew_true for f in frames])
        pitches = np.array([f.pitches_true for f in frames])
        limit = posterior_crlb(model, slew, pitches, FieldEffects().sigma, 1.0 / RATE,
                               CV_PROCESS_NOISE)
        scored = [f.stamp >= WARM_UP_S for f in frames]
        posterior.append(np.array([b.rmse for b, s in zip(limit, scored) if s]))
        squared.append(results['track']['squared'])
        single.append(bounds)
    squared, posterior, single = map(np.concatenate, (squared, posterior, single))
    return {'frames': int(squared.size), 'posterior_ratio': _ratio(squared, posterior),
            'single_ratio': _ratio(squared, single),
            'posterior_over_single': float(np.sqrt(np.mean(posterior ** 2)
                                                   / np.mean(single ** 2)))}


def authors_rows(trials, seed):
    """Score the authors' geometry, each frame from a new estimator (a cold start)."""
    model, joints = xie3dim()
    slew, pitches = angles_from_joints(model, joints)
    rows = []
    for sigma in (1.0, 2.0):
        rng = np.random.default_rng([seed, int(sigma * 10)])
        frames = [model.ranges(joints) + sigma * rng.standard_normal(joints.shape[:1] + (4,))
                  for _ in range(trials)]
        bound = crlb(model, slew, pitches, sigma).rmse
        row = {'sigma_m': sigma, 'bound_m': bound}
        for method in ('chain', 'cepp'):
            errors = []
            for ranges in frames:
                estimator = PostureEstimator(model, method)
                estimator.update(ranges)
                estimate = estimator.last_diagnostics['estimate']
                errors.append(np.sqrt(np.mean(np.sum((estimate - joints) ** 2, axis=1))))
            errors = np.array(errors)
            row[method] = {'ratio': float(np.sqrt(np.mean(errors ** 2)) / bound),
                           'gross': int(np.sum(errors > 5 * bound))}
        rows.append(row)
    return rows


def scipy_chain_fit(residuals, start):
    """Return scipy's LM fit of the chain's angles to ``residuals`` from ``start``, (p+1,)."""
    return least_squares(lambda x: residuals.residuals(x)[0], start,
                         jac=lambda x: residuals.jacobian(x), method='lm', xtol=1e-10).x


def cost_row(seconds, seed):
    """Time per frame of chain and track on the clean case; chain's fit against scipy's."""
    results, _, frames, model = run_case('clean', seconds, seed)
    chain = ChainMethod(model, nlos_fraction=0.0)
    noise = SensorNoise(0.1)
    ours, scipys, agree = [], [], []
    rng = np.random.default_rng(seed)
    for frame in frames[::5]:
        measurements = Measurements.ranges_only(frame.ranges)
        residuals = Residuals(model, measurements, noise)
        truth = np.r_[frame.slew_true, frame.pitches_true]
        start = truth + rng.normal(0.0, 0.02, truth.size)     # a warm start, a frame away
        began = time.perf_counter()
        psi = chain.fit(start, residuals).psi
        ours.append(time.perf_counter() - began)
        began = time.perf_counter()
        fitted = scipy_chain_fit(residuals, start)
        scipys.append(time.perf_counter() - began)
        agree.append(np.max(np.abs(fitted - psi)))
    return {'chain_ms': results['chain']['ms'], 'track_ms': results['track']['ms'],
            'cepp_ms': results['cepp']['ms'],
            'fit_ms': 1e3 * float(np.median(ours)), 'scipy_ms': 1e3 * float(np.median(scipys)),
            'largest_difference_rad': float(np.max(agree))}


@dataclass
class FieldReport:
    """
    The report of ``python3 dev.py bench field`` (see :func:`run`).

    Attributes
    ----------
    seconds : float
        Per run of a case.
    seeds : int
        Runs per case.
    rows : list of dict
        :func:`field_rows`.
    posterior : dict
        :func:`posterior_row`.
    authors : list of dict
        :func:`authors_rows`.
    cost : dict
        :func:`cost_row`.

    """

    seconds: float
    seeds: int
    rows: list
    posterior: dict
    authors: list
    cost: dict
    suite: str = 'field'


@dataclass
class FamilyReport:
    """The report of ``python3 dev.py bench family``: :func:`field_rows` of :data:`FAMILY`."""

    seconds: float
    seeds: int
    rows: list
    suite: str = 'family'


def run_family(seconds=60.0, seeds=2, names=tuple(FAMILY)):
    """Run the cases of :data:`FAMILY` named; the :class:`FamilyReport`."""
    return FamilyReport(seconds, seeds, field_rows(seconds, seeds, names))


def run(seconds=60.0, seeds=2, seed=0, trials=100):
    """Run every part; the :class:`FieldReport` of ``python3 dev.py bench field``."""
    return FieldReport(seconds, seeds, field_rows(seconds, seeds), posterior_row(seconds, seeds),
                       authors_rows(trials, seed), cost_row(seconds, seed))
