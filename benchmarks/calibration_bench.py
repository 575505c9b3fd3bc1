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
``python3 dev.py bench calibration``: calibrate from a recording, then track with the calibration.

Each seed simulates the truck pump (``core.simulate.truck_pump``) in five cases
(:data:`CASES`): tag and anchor range offsets of 0.15 m (standard deviation, per device);
the four outrigger anchors 0.3 m (per axis) from their configured places; both (the
issue's calibration case); both with a fifth of the links blocked, 3 s at a time
(``nlos_persistent``); and both with every other field effect at once (sigma growing with
distance, persistent NLOS, TDMA slots, silent tags). Range noise sigma
is 0.1 m but where a case says otherwise. Each case records ``seconds`` of a working cycle
at 10 Hz and, once a second, a round of anchor-anchor ranges (``FieldSimulator.
anchor_ranges``: ``seconds`` rounds, each direction of each pair), and compares side by
side, with the turret and the cab fixed (they define the truck frame):

- ``configured``: the model as configured;
- ``survey``: the anchor self-survey alone (``core.survey_anchors``), what start-up gives
  before the boom moves: its anchors and anchor offsets, the tag offsets as configured;
- ``calibrated``: ``core.calibrate`` from the tag-anchor ranges alone, learning the range
  noise (``learn_noise``: nobody knows it on site);
- ``+ anchor ranges``: ``core.calibrate`` with the anchor-anchor ranges too;
- ``true``: the pump as it is (its true anchors and offsets), what calibration aims at.

For each: the anchor error (largest over the free anchors), the link offsets' error (tag +
anchor, RMS) beside what the recording can give (the RMS of the reported standard
deviations: the Cramér–Rao bound of the calibration), the computation time; then, on a
fresh recording of the same pump (another seed: motion and noise), chain and track with
the model as RMSE over the clean line-of-sight Cramér–Rao bound at the true noise (first
``WARM_UP_S`` not scored), over every frame and over the frames the method published.
"""
from dataclasses import replace
import time

from epp_ros.core import calibrate, PostureEstimator, survey_anchors
from epp_ros.core.estimation import wrong_frames
from epp_ros.core.model import crlb
from epp_ros.core.simulation import (field_effects, FieldEffects, FieldSimulator,
                                     truck_body_anchors, truck_outriggers, truck_pump,
                                     WorkingMotion)
import numpy as np

__all__ = ['run', 'markdown', 'TARGETS', 'CASES', 'MODELS']

RATE = 10.0             #: frames per second
SURVEY_RATE = 1.0       #: rounds of anchor-anchor ranges per second
WARM_UP_S = 5.0         #: seconds of the fresh recording not scored
OFFSET = 0.15           #: m, std of each tag's and anchor's range offset
SHIFT = 0.3             #: m per axis, std of how far each outrigger anchor is off
SIGMA = 0.1             #: m, range noise
FIXED = truck_body_anchors(truck_pump())     #: the turret and the cab
OUTRIGGERS = truck_outriggers(truck_pump())
METHODS = ('chain', 'track')
MODELS = ('configured', 'survey', 'calibrated', '+ anchor ranges',
          '+ anchor ranges, one link_bias_std', 'true')
#: name: (offsets, outriggers moved, the other field effects at once).
CASES = {
    'offsets': (True, False, ''),
    'anchors_moved': (False, True, ''),
    'both': (True, True, ''),
    'all': (True, True, 'sigma_distance,nlos_persistent,tdma,dropouts'),
    'nlos': (True, True, 'nlos_persistent'),
    'real_uwb': (False, True, 'real_uwb'),
}
#: The issue's targets: metres, metres, seconds, and ratios to the clean bound.
TARGETS = {'anchor_m': 0.05, 'link_offset_m': 0.03, 'seconds': 30.0, 'chain': 1.2,
           'track': 0.8}


def _effects(case):
    """Return the field effects of a case of :data:`CASES`."""
    offsets, moved, others = CASES[case]
    base = field_effects(others) if others else FieldEffects(sigma=SIGMA)
    return replace(base, tag_offset=OFFSET if offsets else base.tag_offset,
                   anchor_offset=OFFSET if offsets else base.anchor_offset,
                   anchor_shift=SHIFT if moved else 0.0, moving_anchors=OUTRIGGERS)


def _simulator(model, effects, seed, truth=None):
    """Return a field simulator of the pump; with ``truth``, the same pump as it."""
    simulator = FieldSimulator(model, effects, np.random.default_rng(seed), 1.0 / RATE)
    if truth is not None:
        simulator.same_pump_as(truth)
    return simulator


def _record(model, simulator, seconds, seed):
    """Return the frames of ``seconds`` of a working cycle and its anchor-anchor rounds."""
    motion = WorkingMotion(model, np.random.default_rng([seed, 1]))
    frames = [simulator.frame(motion, index / RATE) for index in range(int(seconds * RATE))]
    rounds = np.array([simulator.anchor_ranges()
                       for _ in range(max(1, int(seconds * SURVEY_RATE)))])
    return frames, rounds


def _ratios(model, frames, true_model, effects, told):
    """
    Return chain's and track's figures on ``frames`` with ``model`` and ``told`` options.

    RMSE over the clean bound, over every frame and over those published as valid; the
    fraction published; frames published as valid while more than 1 m off, and of those
    the ones whose predicted RMSE was under a third of the error (``field_bench``).
    """
    scored = [frame for frame in frames if frame.stamp >= WARM_UP_S]
    bounds = np.array([crlb(true_model, f.slew_true, f.pitches_true,
                            effects.sigma + effects.sigma_per_metre
                            * true_model.ranges(f.joints)).rmse for f in scored])
    ratios = {}
    for method in METHODS:
        # The outriggers may stand elsewhere than configured, as posture_estimator is told.
        estimator = PostureEstimator(model, method, moving_anchors=OUTRIGGERS, **told)
        squared, valid, predicted = [], [], []
        for frame in frames:
            returned = estimator.update(**frame.inputs())
            if frame.stamp >= WARM_UP_S:
                diagnostics = estimator.last_diagnostics
                estimate = diagnostics.get('estimate', returned)
                squared.append(np.mean(np.sum((estimate - frame.joints) ** 2, axis=1)))
                valid.append(bool(diagnostics['valid']))
                predicted.append(diagnostics.get('predicted_rmse', np.nan))
        squared, valid = np.array(squared), np.array(valid)
        ratios[f'{method} published'] = float(valid.mean())
        ratios[f'{method} wrong'] = wrong_frames(squared, valid, np.array(predicted))
        ratios[method] = float(np.sqrt(np.mean(squared) / np.mean(bounds ** 2)))
        ratios[f'{method} valid'] = float(np.sqrt(np.mean(squared[valid])
                                                  / np.mean(bounds[valid] ** 2))) \
            if valid.any() else float('nan')
    return ratios


def _calibrations(model, frames, rounds, true_model):
    """
    Return each of :data:`MODELS`: its model and facts.

    The facts: verdict, seconds, link-offset std (None but for calibrations), range RMS
    before and after (NaN but for calibrations). A calibration tells the estimator what it
    leaves unknown, each link's own (``CalibrationResult.estimator_options``) as its pump.yaml
    does, or, beside, their RMS for every link (``left_unknown``).
    """
    ranges = np.array([frame.ranges for frame in frames])
    stamps = np.array([frame.stamp for frame in frames])
    began = time.perf_counter()
    survey = survey_anchors(model, rounds, fixed_anchors=FIXED, sigma=SIGMA)
    surveyed = model.with_calibration(survey.anchors, survey.anchor_offsets)
    survey_s = time.perf_counter() - began
    plain = calibrate(model, ranges, stamps=stamps, fixed_anchors=FIXED, sigma=SIGMA,
                      learn_noise=True)
    joint = calibrate(model, ranges, stamps=stamps, fixed_anchors=FIXED, sigma=SIGMA,
                      learn_noise=True, anchor_ranges=rounds)
    nan = float('nan')
    return {'configured': (model, ('', 0.0, None, nan, nan), {}),
            'survey': (surveyed, (survey.status, survey_s, None, nan, nan), {}),
            'calibrated': (plain.model, _facts(plain), plain.estimator_options),
            '+ anchor ranges': (joint.model, _facts(joint), joint.estimator_options),
            '+ anchor ranges, one link_bias_std': (joint.model, _facts(joint),
                                                   joint.left_unknown),
            'true': (true_model, ('', 0.0, None, nan, nan), {})}


def _facts(result):
    """Return a calibration's verdict, seconds, link-offset std, range RMS before, after."""
    return (result.status, result.seconds, result.link_offset_std, result.rms_before,
            result.rms_after)


def run_case(case, seconds, seed):
    """Return one seed's rows of a case: per model its errors, time, verdict and ratios."""
    model = truck_pump()
    effects = _effects(case)
    number = list(CASES).index(case)
    truth = _simulator(model, effects, [seed, number, 0])
    frames, rounds = _record(model, truth, seconds, seed * 100 + number)
    # The links' constant biases too: what a perfect calibration would find.
    true_model = model.with_calibration(truth.true_anchors, truth.anchor_offsets,
                                        truth.tag_offsets,
                                        truth.links.link_offsets + effects.range_bias)
    true_links = true_model.link_offsets()
    fresh, _ = _record(model, _simulator(model, effects, [seed, number, 2], truth), seconds,
                       seed * 100 + number + 10 ** 6)
    free = list(OUTRIGGERS)
    rows = []
    fits = _calibrations(model, frames, rounds, true_model)
    for name, (fitted, (status, seconds_, link_std, before, after), told) in fits.items():
        rows.append({
            'seed': seed, 'case': case, 'model': name, 'status': status,
            'seconds': seconds_, 'rounds': len(rounds), 'rms_before_m': before,
            'rms_after_m': after,
            'anchor_m': float(np.max(np.linalg.norm(fitted.anchors[free]
                                                    - truth.true_anchors[free], axis=1))),
            'link_offset_m': float(np.sqrt(np.mean((fitted.link_offsets() - true_links)
                                                   ** 2))),
            'link_offset_crlb_m': float('nan') if link_std is None
            else float(np.sqrt(np.mean(link_std ** 2))),
            **_ratios(fitted, fresh, true_model, effects, told)})
    return rows


def run_seed(seconds, seed, cases=tuple(CASES)):
    """
    Return one seed's row: the issue's case calibrated with anchor ranges, and every case.

    The row's own keys are the case ``both`` (offsets and outriggers off): the calibration
    with anchor-anchor ranges (``... calibrated``) beside the configured model; ``cases``
    holds the rows of the ``cases`` run (:func:`run_case`), ``both`` always among them.
    """
    cases = [row for case in dict.fromkeys(('both', *cases))
             for row in run_case(case, seconds, seed)]
    pick = {(row['case'], row['model']): row for row in cases}
    main, configured = pick[('both', '+ anchor ranges')], pick[('both', 'configured')]
    keys = ('status', 'seconds', 'anchor_m', 'link_offset_m', 'link_offset_crlb_m',
            'rms_before_m', 'rms_after_m', 'rounds')
    return {'seed': seed, **{key: main[key] for key in keys},
            **{f'{method} configured': configured[method] for method in METHODS},
            **{f'{method} calibrated': main[method] for method in METHODS}, 'cases': cases}


def run(seconds=60.0, seeds=2, seed=0, cases=tuple(CASES)):
    """Run ``seeds`` pumps (seeds ``seed``, ``seed + 1``, ...); the report of the suite."""
    began = time.perf_counter()
    rows = [run_seed(seconds, seed + index, cases) for index in range(seeds)]
    return {'suite': 'calibration', 'seconds': seconds, 'seeds': seeds, 'rows': rows,
            'wall_s': time.perf_counter() - began}


def _cell(value, target, digits=3, scored=True):
    if not np.isfinite(value):
        return '-'
    return f'{value:.{digits}f}' + (' (!)' if scored and value > target else '')


def _line(row):
    """Return a row of the table; targets marked on the calibrated models only."""
    calibrated = row['model'] in ('calibrated', '+ anchor ranges')
    errors = row['case'] in ('both', 'all') and calibrated
    ratios = row['case'] in ('offsets', 'anchors_moved', 'all', 'real_uwb') and calibrated
    crlb_ = row['link_offset_crlb_m']
    return (f'| {row["seed"]} | {row["case"]} | {row["model"]} | {row["status"] or "-"} | '
            f'{_cell(row["anchor_m"], TARGETS["anchor_m"], scored=errors)} | '
            f'{_cell(row["link_offset_m"], TARGETS["link_offset_m"], scored=errors)} | '
            f'{"-" if not np.isfinite(crlb_) else f"{crlb_:.3f}"} | '
            f'{_cell(row["seconds"], TARGETS["seconds"], 1, scored=calibrated)} | '
            + ' | '.join(_cell(row[m], TARGETS[m], 2, scored=ratios) for m in METHODS) + ' | '
            + ' | '.join(_cell(row[f'{m} valid'], TARGETS[m], 2, scored=False)
                         for m in METHODS) + ' | '
            + ' | '.join(f"{row[f'{m} published']:.0%}" for m in METHODS) + ' | '
            + ' | '.join('{} / {}'.format(*row[f'{m} wrong']) for m in METHODS) + ' |')


def _summary(report):
    """Return the lines of the issue's case: one per seed."""
    columns = [f'{method} {name}' for name in ('configured', 'calibrated')
               for method in METHODS]
    lines = ['| seed | verdict | anchors, max [m] | link offsets, RMS [m] | link offsets, CRLB '
             '[m] | time [s] | range RMS before -> after [m] | ' + ' | '.join(columns) + ' |',
             '|---|---|---|---|---|---|---|' + '---|' * len(columns)]
    for row in report['rows']:
        ratios = [_cell(row[c], TARGETS[c.split()[0]], 2, scored=c.endswith('calibrated'))
                  for c in columns]
        lines.append(f'| {row["seed"]} | {row["status"]} | '
                     f'{_cell(row["anchor_m"], TARGETS["anchor_m"])} | '
                     f'{_cell(row["link_offset_m"], TARGETS["link_offset_m"])} | '
                     f'{row["link_offset_crlb_m"]:.3f} | '
                     f'{_cell(row["seconds"], TARGETS["seconds"], 1)} | '
                     f'{row["rms_before_m"]:.3f} -> {row["rms_after_m"]:.3f} | '
                     + ' | '.join(ratios) + ' |')
    return lines


def markdown(report):
    """Return the report as the README's tables: the issue's case, then every case."""
    rounds = report['rows'][0]['rounds'] if report['rows'] else 0
    lines = [f'### Calibration: {report["seconds"]:g} s of working cycle at {RATE:g} Hz and '
             f'{rounds} rounds of anchor-anchor ranges ({SURVEY_RATE:g} Hz); offsets '
             f'{OFFSET:g} m, outriggers {SHIFT:g} m off, sigma {SIGMA:g} m, turret and cab '
             'fixed; then RMSE / clean CRLB on a fresh recording', '',
             "The issue's case (offsets and outriggers off), calibrated with the "
             'anchor-anchor ranges:', '', *_summary(report), '', 'Every case and model:', '',
             '| seed | case | model | verdict | anchors, max [m] | link offsets, RMS [m] | '
             'link offsets, CRLB [m] | time [s] | ' + ' | '.join(METHODS) + ' | '
             + ' | '.join(f'{m}, valid frames' for m in METHODS) + ' | '
             + ' | '.join(f'{m}, published' for m in METHODS) + ' | '
             + ' | '.join(f'{m}, valid > 1 m / confidently' for m in METHODS) + ' |',
             '|---|---|---|---|---|---|---|---|' + '---|' * 4 * len(METHODS)]
    lines += [_line(row) for seed_row in report['rows'] for row in seed_row['cases']]
    lines += ['', f'Cases: offsets {OFFSET:g} m; outriggers {SHIFT:g} m off; both; nlos (both, '
              'and a fifth of the links blocked, 3 s at a time); all (both, '
              f'and {CASES["all"][2].replace(",", ", ")}); real_uwb (outriggers off, and '
              'the errors of real links: core.simulate.FIELD_EFFECTS). Both calibrations '
              'learn the range noise (learn_noise). Link offsets, CRLB: the RMS of the standard '
              'deviations the calibration reports, what the recording can give. Valid '
              'frames: over the frames the method published (as the field bench); valid > 1 m: '
              'frames published as valid while more than 1 m off, and of those the ones '
              'whose predicted RMSE was under a third of the error; a calibration tells the '
              'estimator what it leaves unknown (link_offset_std per link, common_bias_std, '
              'anchor_std), as epp_calibrate writes them; one link_bias_std: the RMS of the '
              "links' for every link instead, as before the pump.yaml carried each link's. "
              f'Targets: anchors <= {TARGETS["anchor_m"] * 100:g} cm and link offsets <= '
              f'{TARGETS["link_offset_m"] * 100:g} cm (cases both and all), <= '
              f'{TARGETS["seconds"]:g} s of computation; with the calibrated model chain <= '
              f'{TARGETS["chain"]} and track <= {TARGETS["track"]} x the clean bound (cases '
              'offsets, anchors_moved, all, real_uwb); (!) misses one.']
    return '\n'.join(lines)
