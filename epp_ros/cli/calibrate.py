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
epp_calibrate: anchor positions and device range offsets from a recorded bag.

    epp_calibrate BAG [--config pump.yaml] [--out calibrated.yaml] [--fixed-anchors NAMES]
                      [--plot FILE.png] [--json] [--force] [--salvage] [--no-survey]
                      [--fit-arm-lengths]

Reads the bag's /uwb/ranges (as uwb_driver publishes them) recorded while the boom slews
and luffs, fits the free anchors' positions, every tag's and anchor's range offset and
each link's own offset under a prior whose size it learns (epp_ros.core.calibration.fit), prints
what changed with its standard deviation, and writes --out: the --config file with
anchor_positions, anchor_offsets, tag_offsets and pair_offsets replaced, and with
link_offset_std (each link's), link_bias_std (their RMS), common_bias_std and anchor_std
set to what the calibration leaves unknown (the estimator weighs each link by its own and
counts them in its predicted stds), everything else kept, for the nodes to
start from (--params-file). The fixed anchors
(--fixed-anchors, names or device ids, comma-separated) are those on the truck body
(turret, cab): their configured positions define the truck frame; default: the first
anchor. The range noise model is the config's range_sigma, nlos_fraction and nlos_gamma.

When the bag also holds /uwb/anchor_ranges (anchors ranging each other: TREK1000 ma lines,
recorded by epp_bag record, written by epp_bag synth --anchor-ranges), every round of them
goes into the fit too, so that the free anchors are self-surveyed and the recording refines
them; the table says how many rounds were used. --no-survey ignores them. A bag without
them is calibrated from /uwb/ranges alone.

Ranges no module measures are left out and counted, never fitted: outside the driver's
[min_range, max_range], longer than the boom can make, or wild (over a metre off the
median of their link's neighbouring frames); a malformed message is skipped and counted.
--out and --plot are checked before the bag is read.

A recording that does not determine every parameter (too short, a parked boom, too little
slewing or luffing) gets its verdict, what to move, and exit status 2, and nothing is
written unless --force; so does a model that fits a tag, an anchor or a link worse than
the others (verdict misfit, naming the likely cause: a section length, an anchor's place,
a link whose bias varies). --fit-arm-lengths fits the sections' lengths too and writes
them. Errors (no such bag, no /uwb/ranges, a bad config) are one line with exit status 2.
"""
import argparse
from dataclasses import dataclass
import json
import os
from pathlib import Path
import stat
import sys
import tempfile
import time

from epp_ros.cli.arguments import Parser

#: Frames (with at least p + 1 ranges) a recording needs before it is tried at all.
MIN_FRAMES = 100
#: Seconds between progress lines on a terminal.
PROGRESS_PERIOD = 0.5


class CalibrationError(Exception):
    """A recording or a request that cannot be calibrated; the message is one line."""


def parse_args(argv):
    parser = Parser(prog='epp_calibrate', description=__doc__.lstrip().splitlines()[0],
                    epilog=__doc__.lstrip().split('\n', 2)[2],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', help='a rosbag2 recording with /uwb/ranges')
    parser.add_argument('--config', help='the pump.yaml the bag was recorded with (default: '
                                         'the packaged one)')
    parser.add_argument('--out', help='write the calibrated pump.yaml here (replaced if it '
                                      'exists; without: nothing written)')
    parser.add_argument('--fixed-anchors', metavar='NAMES',
                        help='comma-separated anchor names or ids on the truck body (default: '
                             'the first anchor)')
    parser.add_argument('--plot', metavar='FILE.png',
                        help='anchors before/after (top view) and residuals per link')
    parser.add_argument('--json', action='store_true', help='also print the result as JSON')
    parser.add_argument('--force', action='store_true',
                        help='write --out even when the recording does not determine every '
                             'parameter (risky: see the verdict)')
    parser.add_argument('--salvage', action='store_true',
                        help='use what can be read of a damaged bag (default: refuse it)')
    parser.add_argument('--no-survey', action='store_true',
                        help="ignore the bag's /uwb/anchor_ranges (no anchor self-survey)")
    parser.add_argument('--fit-arm-lengths', action='store_true',
                        help="fit the sections' lengths too, and write them (the verdict "
                             'says how well the recording determines them: tag-tag ranges '
                             'measure them, lines of sight from the truck hardly do)')
    return parser.parse_args(argv)


def fixed_anchor_indices(config, text):
    """
    Return the indices of the fixed anchors named in ``text``, and how they were chosen.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        The pump: its anchor names and ids.
    text : str or None
        Comma-separated anchor names or device ids; None: the config's ``body_anchors``
        (the first anchor when it names none).

    Returns
    -------
    indices : tuple of int
    note : str
        One line saying which anchors are fixed and why.

    Raises
    ------
    CalibrationError
        On a name that is not an anchor of the config.

    """
    names = config.anchor_names
    if text is None:
        indices = config.body_anchor_indices
        fixed = ', '.join(names[j] for j in indices)
        if config.body_anchors:
            return indices, f'fixed anchors: {fixed} (body_anchors of the config)'
        return indices, (f'fixed anchors: {fixed} (the first anchor: the config does not say '
                         'which anchors are on the truck body; name them in body_anchors or '
                         'with --fixed-anchors, e.g. turret,cab)')
    indices = []
    for item in (part.strip() for part in text.split(',')):
        if item in names:
            index = names.index(item)
        else:
            index = config.anchor_index(item) if item else None
        if index is None:
            raise CalibrationError(f'--fixed-anchors: {item!r} is not an anchor of the config '
                                   f'(anchors: {", ".join(names)})')
        if index not in indices:
            indices.append(index)
    return tuple(indices), f'fixed anchors: {", ".join(names[j] for j in indices)}'


def noise_settings(document):
    """
    Return calibrate's noise keywords from a pump.yaml's settings, as the estimator reads them.

    ``range_sigma``, ``tag_sigma``, ``nlos_fraction``, ``nlos_gamma`` and ``learn_noise``
    (``epp_ros.app.settings``: the node's defaults and ranges).

    Raises
    ------
    CalibrationError
        On a setting the node would refuse.

    """
    from epp_ros.app.settings import file_settings
    try:
        told = file_settings(document['/**']['ros__parameters'],
                             ('range_sigma', 'tag_sigma', 'nlos_fraction', 'nlos_gamma',
                              'learn_noise'))
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    # learn_noise as the estimator: nobody knows a site's noise
    return {'sigma': told['range_sigma'], 'tag_sigma': told['tag_sigma'],
            'nlos_fraction': told['nlos_fraction'], 'nlos_gamma': told['nlos_gamma'],
            'learn_noise': told['learn_noise']}


def range_window(document):
    """
    Return the plausible ranges ``(min_range, max_range)``, metres, of a pump.yaml's settings.

    They are the driver's: a recording of ranges it would have dropped is refused, not fitted.

    Raises
    ------
    CalibrationError
        On limits that are not finite numbers with 0 <= min_range < max_range.

    """
    import math

    from epp_ros.uwb.frames import MAX_RANGE, MIN_RANGE
    section = document['/**']['ros__parameters']
    try:
        low, high = (float(section.get('min_range', MIN_RANGE)),
                     float(section.get('max_range', MAX_RANGE)))
    except (TypeError, ValueError):
        low = high = float('nan')
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low < high):
        raise CalibrationError('min_range, max_range: need finite numbers with 0 <= min_range '
                               f'< max_range, got {section.get("min_range")!r}, '
                               f'{section.get("max_range")!r}')
    return low, high


@dataclass
class RangeRecording:
    """
    A bag's ``/uwb/ranges`` as calibrate takes them, and what of them was left out.

    Attributes
    ----------
    ranges : ndarray, shape (N, p, m)
        Metres, NaN where not measured or implausible.
    tag_ranges : ndarray, shape (N, p, p)
    stamps : ndarray, shape (N,)
        Seconds, increasing.
    damage : str or None
        What of a damaged bag was skipped (``--salvage``).
    malformed : int
        Messages that could not be read as ranges (left out).
    first_malformed : str or None
        Why the first of them was.
    implausible : int
        Ranges outside ``[min_range, max_range]`` or longer than the boom can make
        (``core.measurements.plausible_limits``), left out.
    spikes : int
        Wild ranges, far off their link's neighbouring frames
        (``core.measurements.range_spikes``), left out.

    """

    ranges: object
    tag_ranges: object
    stamps: object
    damage: object = None
    malformed: int = 0
    first_malformed: object = None
    implausible: int = 0
    spikes: int = 0

    def left_out(self, window):
        """Return a line on what was left out, or None when nothing was."""
        from epp_ros.core.model import SPIKE_M
        parts = []
        if self.implausible:
            parts.append(f'{self.implausible} ranges outside [{window[0]:g}, {window[1]:g}] m '
                         "or beyond the boom's reach")
        if self.spikes:
            parts.append(f'{self.spikes} wild ranges (over {SPIKE_M:g} m off the median of '
                         "their link's neighbouring frames)")
        if self.malformed:
            parts.append(f'{self.malformed} malformed messages (the first: '
                         f'{self.first_malformed})')
        return f'left out {" and ".join(parts)}' if parts else None


def read_ranges(path, config, window, salvage=False, progress=None):
    """
    Read a bag's ``/uwb/ranges`` into the arrays calibrate takes.

    Messages are decoded and arranged by ``PumpConfig.link_frame``, as ``epp_bag eval``
    reads them, in the order of their stamps. Implausible ranges are left out (NaN) and
    malformed messages skipped, both counted: a few bad ones must not refuse a recording,
    nor steer the fit.

    Parameters
    ----------
    path : path
        The bag.
    config : epp_ros.app.config.PumpConfig
        The pump: link names of the messages, and the boom whose reach bounds the ranges.
    window : tuple of float
        ``(min_range, max_range)``, metres (:func:`range_window`).
    salvage : bool
        Use what can be read of a damaged bag.
    progress : callable, optional
        Called with (messages done, messages in all).

    Returns
    -------
    RangeRecording

    Raises
    ------
    epp_ros.app.bags.BagError
        On a bag that cannot be read, without /uwb/ranges, or whose labels name no link.

    """
    import numpy as np

    from epp_ros.app import bags
    summary = bags.info(path)
    topics = {entry['topic']: entry['type'] for entry in summary['topics']}
    if bags.RANGES not in topics:
        raise bags.BagError(f'{path}: no {bags.RANGES} topic (topics: {sorted(topics)})')
    if topics[bags.RANGES] != bags.TYPES[bags.RANGES]:
        raise bags.BagError(f'{path}: {bags.RANGES} holds {topics[bags.RANGES]}, expected '
                            f'{bags.TYPES[bags.RANGES]}')
    messages, damage = bags.read_all(path, salvage=salvage, topics=[bags.RANGES])
    p, m = len(config.tag_names), len(config.anchor_names)
    ranges = np.full((len(messages), p, m), np.nan)
    tag_ranges = np.full((len(messages), p, p), np.nan)
    stamps = np.full(len(messages), np.nan)
    unknown, problems = 0, []
    for index, (_, msgtype, _, raw, _) in enumerate(messages):
        try:
            message = bags.TYPESTORE.deserialize_cdr(raw, msgtype)
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on bad bytes
            problems.append(f'undecodable ({type(exc).__name__})')
            continue
        try:
            frame = config.link_frame(list(message.name), message.position, message.effort)
        except ValueError as exc:
            problems.append(str(exc))
            continue
        stamps[index] = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        ranges[index], tag_ranges[index] = frame.ranges, frame.tag_ranges
        unknown += frame.unknown
        if progress is not None:
            progress(index + 1, len(messages))
    if messages and unknown and not np.isfinite(ranges).any():
        raise bags.BagError(f'{path}: no {bags.RANGES} label names a tag-anchor pair of the '
                            'config (recorded with another pump.yaml? see --config)')
    whole = np.isfinite(stamps)
    order = np.flatnonzero(whole)[np.argsort(stamps[whole], kind='stable')]
    ranges, tag_ranges = ranges[order], tag_ranges[order]
    implausible, spikes = _leave_out_implausible(config.model(), window, ranges, tag_ranges)
    return RangeRecording(ranges, tag_ranges, stamps[order],
                          None if damage.intact else damage.describe(), len(problems),
                          problems[0] if problems else None, implausible, spikes)


def _leave_out_implausible(model, window, ranges, tag_ranges):
    """
    Set ranges (N, p, m) and tag ranges (N, p, p) nobody could measure to NaN.

    Returns how many were implausible alone, and how many wild (``range_spikes``).
    """
    import numpy as np

    from epp_ros.core.model import plausible_limits, range_spikes
    range_limit, tag_limit = plausible_limits(model)
    implausible = spikes = 0
    for values, limit in ((ranges, range_limit), (tag_ranges, tag_limit)):
        wrong = _implausible(values, window, limit)
        values[wrong] = np.nan
        wild = range_spikes(values)
        values[wild] = np.nan
        implausible, spikes = implausible + int(wrong.sum()), spikes + int(wild.sum())
    return implausible, spikes


def _implausible(values, window, limit):
    """Mask of the measured ``values`` outside ``window`` (low, high) or over ``limit``."""
    import numpy as np
    inside = (values >= window[0]) & (values <= window[1]) & (values <= limit)
    return ~np.isnan(values) & ~inside


def read_survey(path, config, window, salvage=False, ignore=False):
    """
    Return a bag's rounds of anchor-anchor ranges for the self-survey, and a line about them.

    Parameters
    ----------
    path : path
        The bag.
    config : epp_ros.app.config.PumpConfig
        The pump: the anchors' names and configured places.
    window : tuple of float
        ``(min_range, max_range)``, metres: ranges outside, or over twice the configured
        distance plus 10 m, are left out.
    salvage : bool
        Use what can be read of a damaged ``/uwb/anchor_ranges``.
    ignore : bool
        ``--no-survey``: do not read them.

    Returns
    -------
    rounds : ndarray, shape (K, m, m), or None
        Metres, NaN where not measured; None without any range (nothing to survey with).
    line : str
        ``Anchor self-survey: ...`` for the table.

    Raises
    ------
    epp_ros.app.bags.BagError
        On a ``/uwb/anchor_ranges`` that cannot be read.

    """
    import numpy as np

    from epp_ros.app import bags
    if ignore:
        return None, f'Anchor self-survey: off (--no-survey: {bags.ANCHOR_RANGES} ignored)'
    malformed = []
    try:
        rounds = bags.read_anchor_ranges(path, config, salvage, malformed)
    except bags.BagError as exc:
        raise bags.BagError(f'{exc} (--no-survey calibrates without them)') from None
    anchors = config.model().anchors
    limit = 2.0 * np.linalg.norm(anchors[:, None] - anchors[None], axis=-1) + 10.0
    wrong = _implausible(rounds, window, limit)
    rounds[wrong] = np.nan
    rounds = rounds[np.isfinite(rounds).any(axis=(1, 2))]
    skipped = ''.join((
        f'; left out {int(wrong.sum())} implausible ranges' if wrong.any() else '',
        f'; left out {len(malformed)} malformed messages (the first: {malformed[0]})'
        if malformed else ''))
    if not len(rounds):
        usable = 'usable ' if skipped else ''
        return None, (f'Anchor self-survey: none (no {usable}{bags.ANCHOR_RANGES} in the bag'
                      f'{skipped})')
    pairs = int(np.isfinite(rounds).any(axis=0).sum())
    return rounds, (f'Anchor self-survey: yes, {len(rounds)} rounds of {bags.ANCHOR_RANGES} '
                    f'({pairs} anchor pairs, {int(np.isfinite(rounds).sum())} ranges{skipped})')


class Progress:
    """Throttled progress lines on stderr, on a terminal only."""

    def __init__(self, stream=None):
        self.stream = sys.stderr if stream is None else stream
        self.shown = 0.0
        self.active = bool(getattr(self.stream, 'isatty', lambda: False)())

    def __call__(self, done, total):
        """Show ``done`` of ``total`` messages read, at most every PROGRESS_PERIOD s."""
        now = time.monotonic()
        if not self.active or (done < total and now - self.shown < PROGRESS_PERIOD):
            return
        self.shown = now
        self.stream.write(f'\repp_calibrate: reading /uwb/ranges {done}/{total} '
                          f'({100 * done / max(total, 1):.0f} %)')
        if done == total:
            self.stream.write('\n')
        self.stream.flush()

    def say(self, text):
        """Show one line of status (on a terminal)."""
        if self.active:
            self.stream.write(f'epp_calibrate: {text}\n')
            self.stream.flush()


def _vector(values, std=None):
    cells = ', '.join(f'{v:7.3f}' for v in values)
    if std is None:
        return f'({cells})'
    return f'({cells}) +- ({", ".join(f"{s:.3f}" for s in std)})'


def report_lines(config, before, result, fixed, survey=None):
    """
    Return the table of what changed, as lines.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        Names of the anchors and tags.
    before : BoomModel
        The configured model.
    result : CalibrationResult
        What calibrate found.
    fixed : tuple of int
        The fixed anchors.
    survey : str, optional
        The line saying whether the anchors were self-surveyed (:func:`read_survey`).

    """
    import numpy as np
    names = config.anchor_names
    width = max(len(name) for name in (*names, *config.tag_names)) + 9
    lines = ['Anchors [m]: configured -> calibrated +- std (x, y, z), moved', ]
    for j, name in enumerate(names):
        label = f'{name} (fixed)' if j in fixed else name
        moved = float(np.linalg.norm(result.anchors[j] - before.anchors[j]))
        std = None if j in fixed else result.anchor_std[j]
        lines.append(f'  {label:<{width}} {_vector(before.anchors[j])} -> '
                     f'{_vector(result.anchors[j], std)}  {moved:.3f}')
    if survey:
        lines.append(survey)
    if result.arm_length_std.any():
        lines.append('Arm lengths [m]: configured -> calibrated +- std')
        for k, tag in enumerate(config.tag_names):
            lines.append(f'  {"section " + str(k + 1):<{width}} {before.arm_lengths[k]:7.3f} -> '
                         f'{result.arm_lengths[k]:7.3f} +- {result.arm_length_std[k]:.3f}')
    lines.append('Range offsets [m]: configured -> calibrated +- std')
    for kind, labels, old, new, std in (
            ('anchor', names, before.anchor_offsets, result.anchor_offsets,
             result.anchor_offset_std),
            ('tag', config.tag_names, before.tag_offsets, result.tag_offsets,
             result.tag_offset_std)):
        for label, a, b, s in zip(labels, old, new, std):
            lines.append(f'  {kind + " " + label:<{width}} {a:7.3f} -> {b:7.3f} +- {s:.3f}')
    lines.append(f'  (gauge: {result.gauge})')
    lines.append(f"Links' own offsets: {1000 * np.sqrt(np.mean(result.pair_offsets ** 2)):.0f} "
                 f'mm RMS (their size learned: {1000 * result.link_std:.0f} mm); residuals '
                 f'correlated over {result.correlation:.1f} frames')
    lines.append('Link offsets (tag + anchor + own) [m], calibrated +- std:')
    cell = max(17, max(len(name) for name in names) + 2)
    lines.append('  ' + ' ' * width + ''.join(f'{name:>{cell}}' for name in names))
    for k, tag in enumerate(config.tag_names):
        lines.append(f'  {tag:<{width}}' + ''.join(
            f'{f"{v:.3f} +- {s:.3f}":>{cell}}'
            for v, s in zip(result.link_offsets[k], result.link_offset_std[k])))
    used = int(result.frames_used.sum())
    lines.append(f'Range residual RMS: {result.rms_before:.3f} m -> {result.rms_after:.3f} m '
                 f'({used} frames, {result.iterations} iterations, condition '
                 f'{result.condition:.3g}, {result.seconds:.1f} s)')
    lines.append('Left unknown (written for the estimator): ' + ', '.join(
        f'{name} {value:.3f} m' for name, value in result.left_unknown.items()))
    lines.append(f'Verdict: {result.status}: {result.message}')
    return lines


def result_json(config, before, result, fixed, written, survey_rounds=0):
    """Return the calibration as a JSON-ready dict (names -> values, metres)."""
    return {
        'status': result.status, 'message': result.message, 'written': written,
        'survey_rounds': int(survey_rounds),
        'fixed_anchors': [config.anchor_names[j] for j in fixed],
        'anchors': {name: {'before': before.anchors[j].tolist(),
                           'after': result.anchors[j].tolist(),
                           'std': result.anchor_std[j].tolist()}
                    for j, name in enumerate(config.anchor_names)},
        'anchor_offsets': {name: {'before': float(before.anchor_offsets[j]),
                                  'after': float(result.anchor_offsets[j]),
                                  'std': float(result.anchor_offset_std[j])}
                           for j, name in enumerate(config.anchor_names)},
        'tag_offsets': {name: {'before': float(before.tag_offsets[k]),
                               'after': float(result.tag_offsets[k]),
                               'std': float(result.tag_offset_std[k])}
                        for k, name in enumerate(config.tag_names)},
        'link_offsets': result.link_offsets.tolist(),
        'link_offset_std': result.link_offset_std.tolist(),
        'pair_offsets': result.pair_offsets.tolist(), 'link_std': result.link_std,
        'correlation_frames': result.correlation,
        **result.left_unknown,
        'arm_lengths': {'before': before.arm_lengths.tolist(),
                        'after': result.arm_lengths.tolist(),
                        'std': result.arm_length_std.tolist()},
        'rms_before_m': result.rms_before, 'rms_after_m': result.rms_after,
        'condition': result.condition, 'poorly_determined': list(result.poorly_determined),
        'gauge': result.gauge, 'frames_used': int(result.frames_used.sum()),
        'iterations': result.iterations, 'seconds': result.seconds}


def write_config(path, source_text, result):
    """
    Write the calibrated pump.yaml atomically (a temporary file renamed into place).

    A symbolic link keeps pointing at the file, which is replaced; a replaced file keeps
    its permissions, a new one gets those the umask gives.

    Returns
    -------
    str
        The text written.

    """
    from epp_ros.app.pump_yaml import update_pump_yaml
    values = {'anchor_positions': result.anchors.ravel().tolist(),
              'anchor_offsets': result.anchor_offsets.tolist(),
              'tag_offsets': result.tag_offsets.tolist(),
              'pair_offsets': result.pair_offsets.ravel().tolist(),
              'link_offset_std': result.link_bias_stds.ravel().tolist(),
              **result.left_unknown}
    if result.arm_length_std.any():         # fitted (--fit-arm-lengths)
        values['arm_lengths'] = result.arm_lengths.tolist()
    text = update_pump_yaml(source_text, values)
    path = Path(path).resolve()
    handle, temporary = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent)
    try:
        os.fchmod(handle, _mode_of(path))
        with os.fdopen(handle, 'w') as stream:
            stream.write(text)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return text


def _mode_of(path):
    """Permissions of the file ``path``, or what a new file gets from the umask."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except FileNotFoundError:
        umask = os.umask(0o022)
        os.umask(umask)
        return 0o666 & ~umask


def link_residuals(model, ranges, result):
    """
    Return the RMS range residual (p, m) of each link, metres, over the frames fitted.

    Links judged blocked (NLOS probability over a half) do not count.
    """
    import numpy as np
    used = result.frames_used
    psi = result.postures[used]
    joints = model.forward_kinematics(psi[:, 0], psi[:, 1:])
    predicted = (np.linalg.norm(joints[:, :, None] - model.anchors[None, None], axis=-1)
                 + model.link_offsets())
    error = ranges[used] - predicted
    keep = np.isfinite(error) & (result.nlos[used] < 0.5)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.sqrt((np.where(keep, error, 0.0) ** 2).sum(axis=0) / keep.sum(axis=0))


def plot(path, config, before, result, ranges, fixed):
    """Write a PNG: anchors before/after from above, and each link's residual RMS."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    import numpy as np
    figure, (top, bars) = pyplot.subplots(1, 2, figsize=(13, 5.5))
    top.plot(*before.base[:2], 'k+', markersize=12, label='slew axis')
    top.scatter(before.anchors[:, 0], before.anchors[:, 1], facecolors='none',
                edgecolors='tab:gray', s=80, label='configured')
    top.scatter(result.anchors[:, 0], result.anchors[:, 1], c='tab:red', s=30,
                label='calibrated')
    for j, name in enumerate(config.anchor_names):
        top.annotate('', result.anchors[j, :2], before.anchors[j, :2],
                     arrowprops={'arrowstyle': '->', 'color': 'tab:red'})
        shift = np.linalg.norm(result.anchors[j] - before.anchors[j])
        top.annotate(f'{name}{" (fixed)" if j in fixed else ""}\n{shift:.3f} m',
                     result.anchors[j, :2], textcoords='offset points', xytext=(6, 6),
                     fontsize=8)
    top.set_aspect('equal', 'datalim')
    top.set_xlabel('x [m]')
    top.set_ylabel('y [m]')
    top.set_title('Anchors from above')
    top.grid(True)
    top.legend(fontsize=8)
    after = link_residuals(result.model, ranges, result)
    configured = link_residuals(before, ranges, result)
    labels = config.link_names
    positions = np.arange(len(labels))
    bars.bar(positions - 0.2, configured.ravel(), 0.4, color='tab:gray',
             label='configured model, at the calibrated postures')
    bars.bar(positions + 0.2, after.ravel(), 0.4, color='tab:red', label='calibrated')
    bars.set_xticks(positions, labels, rotation=90, fontsize=7)
    bars.set_ylabel('range residual RMS [m]')
    bars.set_title(f'Residuals per link ({result.status}: RMS {result.rms_before:.3f} -> '
                   f'{result.rms_after:.3f} m)')
    bars.grid(True, axis='y')
    bars.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    pyplot.close(figure)


def run(args, out=None):
    """Calibrate as the arguments say, printing to ``out`` (stdout); return the exit status."""
    out = sys.stdout if out is None else out
    import numpy as np
    import yaml

    from epp_ros.app import bags
    from epp_ros.app.config import default_config_path, load_pump_config
    progress = Progress()
    config_path = Path(args.config) if args.config else default_config_path()
    config = load_pump_config(config_path)
    source_text = config_path.read_text()
    document = yaml.safe_load(source_text)
    settings, window = noise_settings(document), range_window(document)
    fixed, note = fixed_anchor_indices(config, args.fixed_anchors)
    _check_outputs(args)
    recording = read_ranges(args.bag, config, window, args.salvage, progress)
    ranges = recording.ranges
    if recording.damage:
        print(f'epp_calibrate: salvaged {args.bag}: {recording.damage}', file=sys.stderr)
    left_out = recording.left_out(window)
    p = len(config.tag_names)
    usable = int(np.sum(np.isfinite(ranges).sum(axis=(1, 2)) >= p + 1))
    if usable < MIN_FRAMES:
        why = f' ({left_out})' if left_out else ''
        raise CalibrationError(
            f'{args.bag}: {usable} frames with {p + 1} or more plausible ranges{why}, '
            f'{MIN_FRAMES} needed: record the boom slewing and luffing for a minute or more; '
            'nothing written')
    if left_out:
        print(f'epp_calibrate: {args.bag}: {bags.RANGES}: {left_out}', file=sys.stderr)
    survey, survey_line = read_survey(args.bag, config, window, args.salvage, args.no_survey)
    before = config.model()
    print(f'{args.bag}: {len(ranges)} frames of /uwb/ranges ({usable} usable), '
          f'{p} tags, {len(config.anchor_names)} anchors; {note}', file=out)
    progress.say(f'calibrating {usable} frames ...')
    result = _calibration(args, before, (ranges, recording.tag_ranges, recording.stamps,
                                         survey), fixed, settings)
    for line in report_lines(config, before, result, fixed, survey_line):
        print(line, file=out)
    written = _written(args, source_text, result, out)
    if args.plot:
        plot(args.plot, config, before, result, ranges, fixed)
        print(f'plotted {args.plot}', file=out)
    if args.json:
        print(json.dumps(result_json(config, before, result, fixed, written,
                                     0 if survey is None else len(survey))), file=out)
    if not result.success:
        print(f'epp_calibrate: {args.bag}: {result.status}: {result.message}',
              file=sys.stderr)
        return 0 if written else 2
    return 0


def _check_outputs(args):
    """Refuse --out and --plot paths that could not be written, before the long fit."""
    from epp_ros.cli.arguments import image_path_problem, replaced_file_problem
    problem = ((args.out and replaced_file_problem('--out', args.out, keep_out=(args.bag,)))
               or (args.plot and image_path_problem('--plot', args.plot)))
    if problem:
        raise CalibrationError(problem)


def _calibration(args, before, recording, fixed, settings):
    """
    Return ``core.calibrate``'s result on the recording, or raise CalibrationError.

    ``recording``: the ranges, tag-tag ranges, stamps and anchor-anchor rounds (None).
    """
    import numpy as np

    from epp_ros.core import calibrate
    ranges, tag_ranges, stamps, survey = recording
    # Passed only when there are some: a bag without them calibrates as it always did.
    optional = {} if survey is None else {'anchor_ranges': survey}
    if np.isfinite(tag_ranges).any():
        optional['tag_ranges'] = tag_ranges
    try:
        return calibrate(before, ranges, stamps=stamps, fixed_anchors=fixed, **optional,
                         fit_arm_lengths=args.fit_arm_lengths, **settings)
    except ValueError as exc:
        text = str(exc).splitlines()[0]
        text = text if len(text) <= 120 else text[:117] + '...'
        hint = '' if survey is None else ' (or try --no-survey)'
        raise CalibrationError(f'{args.bag}: cannot calibrate ({text}): the recording hardly '
                               'determines the parameters; record the boom slewing and '
                               f'luffing through its range{hint}; nothing written') from None


def _written(args, source_text, result, out):
    """Write the calibrated config when the verdict (or ``--force``) allows; its path."""
    from epp_ros.app.config import ConfigError
    if args.out is None:
        return None
    if not (result.success or args.force):
        print(f'nothing written to {args.out}: the verdict is {result.status} (--force '
              'writes it anyway, at your risk)', file=out)
        return None
    try:
        write_config(args.out, source_text, result)
    except ConfigError as exc:
        raise CalibrationError(f'the calibrated config does not validate ({exc}); '
                               'nothing written') from None
    except OSError as exc:
        raise CalibrationError(f'cannot write {args.out}: {exc}') from None
    print(f'wrote {args.out}: start the nodes with --params-file {args.out}', file=out)
    if not result.success:
        doubtful = ', '.join(result.poorly_determined) or 'every value'
        print(f'epp_calibrate: warning: --force wrote {args.out} although the verdict is '
              f'{result.status}: {doubtful} may be further off than if left as configured',
              file=sys.stderr)
    return str(args.out)


def main(argv=None):
    """Run ``epp_calibrate``; return the exit status."""
    try:
        args = parse_args(sys.argv[1:] if argv is None else argv)
        from epp_ros.app import bags
        from epp_ros.app.config import ConfigError
        from epp_ros.app.threads import single_blas_thread
        single_blas_thread()
        try:
            return run(args)
        except (bags.BagError, ConfigError, CalibrationError) as exc:
            print(f'epp_calibrate: {exc.args[0] if exc.args else exc}', file=sys.stderr)
            return 2
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
