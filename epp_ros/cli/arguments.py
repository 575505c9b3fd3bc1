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
Command-line numbers, addresses, field effects and output paths, checked where parsed.

Every numeric option of the console scripts is finite and in its range, and every output
path writable, so that a typo gives one line and exit status 2 before any work, never a
traceback, an all-NaN file or a lost run.
"""
import argparse
import math

__all__ = ['Parser', 'number', 'integer', 'host_port', 'field_names', 'add_field_options',
           'settle_noise_options', 'RATE_HZ', 'NOISE_M', 'FRACTION', 'DURATION_S', 'SEED',
           'writable_folder', 'new_path_problem', 'image_path_problem',
           'replaced_file_problem']


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (``prog: error: ...``) and exit 2."""

    def error(self, message):
        """Print one line naming the problem and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {message} (see --help)\n')


def number(low, high, low_open=False, high_open=False):
    """
    Return an argparse ``type`` for a finite float in ``[low, high]``.

    Parameters
    ----------
    low, high : float
        The range, inclusive unless ``low_open`` or ``high_open``.
    low_open, high_open : bool
        Exclude that end.

    """
    left, right = '(' if low_open else '[', ')' if high_open else ']'

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
        inside = (math.isfinite(value) and (value > low if low_open else value >= low)
                  and (value < high if high_open else value <= high))
        if not inside:
            raise argparse.ArgumentTypeError(
                f'{text} is not in {left}{low:g}, {high:g}{right}')
        return value
    parse.__name__ = 'number'
    return parse


def integer(low, high):
    """
    Return an argparse ``type`` for an integer in ``[low, high]``.

    Parameters
    ----------
    low, high : int
        The range, inclusive.

    """
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f'{text} is not in [{low}, {high}]')
        return value
    parse.__name__ = 'integer'
    return parse


#: The simulated pump's options, one range each, for every tool that runs it (the emulator
#: and the demo, which passes them on).
RATE_HZ = number(0, 1000, low_open=True)
NOISE_M = number(0, 100)
FRACTION = number(0, 1)
DURATION_S = number(0, 1e7, low_open=True)
SEED = integer(0, 2 ** 63 - 1)


def host_port(text):
    """
    Parse ``HOST:PORT`` with a port in 0-65535 (0: one the system picks; an argparse type).

    Returns
    -------
    (str, int)
        The host and the port.

    """
    host, _, port = text.rpartition(':')
    if not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise argparse.ArgumentTypeError(f'{text!r} is not HOST:PORT with a port 0-65535')
    return host, int(port)


def field_names(text):
    """Return ``text`` if it names presets of ``core.simulate.FIELD_EFFECTS`` (a type)."""
    from epp_ros.core.simulation import field_effects
    try:
        field_effects(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def settle_noise_options(parser, args, defaults):
    """
    Refuse ``--field`` with the noise options it replaces; without it, fill in their defaults.

    ``defaults`` maps each option's name (``sigma``, ``nlos``, ``drop``) to its default;
    the options are parsed with default None, so that one given can be told apart.
    """
    given = [f'--{name}' for name in defaults if getattr(args, name) is not None]
    if args.field and given:
        parser.error(f'--field sets the range errors itself: give it or {"/".join(given)}, '
                     'not both')
    if not args.field:
        for name, default in defaults.items():
            if getattr(args, name) is None:
                setattr(args, name, default)


def field_effects_of(args, nlos_gamma, moving_anchors=None):
    """
    Return the field effects of ``--field``, or else of ``--sigma/--nlos/--drop``.

    Parameters
    ----------
    args : argparse.Namespace
        With ``field``, and ``sigma``, ``nlos`` and ``drop`` (settled).
    nlos_gamma : float
        Mean NLOS excess of ``--nlos``, metres.
    moving_anchors : tuple of int, optional
        The anchors that may move with each set-up (``PumpConfig.moving_anchor_indices``):
        the ones ``anchors_moved`` moves. None: every anchor but the base one.

    Returns
    -------
    epp_ros.core.simulation.simulate.FieldEffects

    """
    from dataclasses import replace
    from epp_ros.core.simulation import FieldEffects, field_effects
    if args.field:
        effects = field_effects(args.field)
    else:   # nlos_duration 0: each link blocked anew each cycle, as RangeNoise does
        effects = FieldEffects(sigma=args.sigma, nlos_fraction=args.nlos, nlos_duration=0.0,
                               nlos_gamma=nlos_gamma, link_dropout=args.drop)
    if moving_anchors is not None and effects.moving_anchors is None:
        effects = replace(effects, moving_anchors=tuple(moving_anchors))
    return effects


def add_field_options(parser):
    """Add ``--field`` (presets of ``core.simulate.FIELD_EFFECTS``) and ``--motion``."""
    from epp_ros.core.simulation import FIELD_EFFECTS, MOTIONS
    parser.add_argument('--field', metavar='NAMES', type=field_names,
                        help='simulate field effects instead of --sigma/--nlos/--drop: '
                             'comma-separated presets of ' + ', '.join(FIELD_EFFECTS))
    parser.add_argument('--motion', choices=MOTIONS, default='working',
                        help='working: the smooth pouring cycle; joystick: abrupt starts, '
                             'stops and reversals (default working)')


def writable_folder(folder):
    """Tell whether this user can make a file in ``folder`` (tried: root may not write /proc)."""
    import tempfile
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def new_path_problem(option, path):
    """
    Say what stops ``option`` from creating ``path`` (a bag, a folder), or return None.

    Checked before any work, so that a long run never ends in a path it cannot write.
    """
    from pathlib import Path
    path = Path(path)
    if path.exists() or path.is_symlink():
        return f'{option} {path}: exists already'
    folder = path.resolve().parent
    if not writable_folder(folder):
        return f'{option} {path}: {folder} is not a folder this user can write to'
    return None


def image_path_problem(option, path):
    """Say what stops ``option`` from writing the image ``path``, or return None."""
    from pathlib import Path
    path = Path(path)
    folder = path.resolve().parent
    if path.is_dir():
        return f'{option} {path}: is a folder'
    if not writable_folder(folder):
        return f'{option} {path}: {folder} is not a folder this user can write to'
    from matplotlib.figure import Figure
    kinds = Figure().canvas.get_supported_filetypes()
    if path.suffix.lstrip('.').lower() not in kinds:
        return f'{option} {path}: not one of the image types {", ".join(sorted(kinds))}'
    return None


def replaced_file_problem(option, path, keep_out=()):
    """
    Say what stops ``option`` from replacing the text file ``path``, or return None.

    ``path`` may be absent, a regular file, or a symbolic link to either (the link's
    target is replaced, the link kept). A folder, a FIFO, a device or a socket is refused,
    and so is anything inside a rosbag2 folder or inside ``keep_out`` (e.g. the bag read).
    """
    from pathlib import Path
    path = Path(path)
    target = path.resolve()
    if target.exists() and not target.is_file():
        kind = 'a folder' if target.is_dir() else 'not a regular file'
        return f'{option} {path}: is {kind}'
    folder = target.parent
    for guarded in keep_out:
        guarded = Path(guarded).resolve()
        if target == guarded or guarded in target.parents:
            return f'{option} {path}: is inside {guarded}, which is read'
    if any(folder.glob('*.mcap')) or any(folder.glob('*.db3')):
        return f'{option} {path}: {folder} is a rosbag2 folder'
    if not writable_folder(folder):
        return f'{option} {path}: {folder} is not a folder this user can write to'
    return None
