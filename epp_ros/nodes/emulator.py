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
uwb_emulator: a simulated pump whose UWB modules talk like the real ones.

The boom follows a working cycle, or with ``--motion joystick`` an operator's joysticks;
each cycle's noisy ranges are written, in any format of the registry
(:data:`epp_ros.uwb.formats.FORMATS`), to a pseudo-terminal (like a USB-UART) or to TCP
clients (like the ESP8266 WiFi bridge). The first stdout lines say where:
``PTY <device path>`` or ``TCP <url>``, one per channel (formats that do not name the tag
need one channel per tag, formats that name no device one per tag-anchor pair; the ids the
lines leave out follow). With ``--truth`` the true posture is published as
``geometry_msgs/PoseArray`` on ``arm_posture/ground_truth`` (base first, then joints 1..p),
stamped with the node's clock (simulated time with ``use_sim_time``), which also paces the
cycles and measures ``--duration``.

The ranges carry ``--sigma``/``--nlos``/``--drop`` noise, drawn anew each cycle. With
``--field NAMES`` (presets of :data:`epp_ros.core.simulation.FIELD_EFFECTS`, comma-separated)
or ``--motion joystick`` they come from :class:`epp_ros.core.simulation.simulate.FieldSimulator`
instead: the presets' effects, or, without ``--field``, the same noise as above. ``--field``
replaces the noise options, so giving both is refused.

Formats whose devices report anchor-anchor ranges (TREK1000: ``ma`` lines of anchor A0)
also print them, from the field simulator (``FieldSimulator.anchor_ranges``: the true,
possibly displaced anchors, their offsets and the range noise; the configured anchors and
the noise options without ``--field``): a burst of ``SURVEY_BURST`` rounds before the first
ranging cycle, then one round a second (:func:`epp_ros.uwb.emulation.anchor_rounds`).
"""
import sys

from epp_ros.app import contract
from epp_ros.app.config import ConfigError, load_pump_config
from epp_ros.cli.arguments import (add_field_options, DURATION_S, field_effects_of, FRACTION,
                                   host_port, NOISE_M, Parser, RATE_HZ, SEED, settle_noise_options)
from epp_ros.core.simulation import FieldSimulator, make_motion, Motion, RangeNoise, working_cycle
from epp_ros.nodes.messages import posture_message, TRUTH_QOS
from epp_ros.nodes.runtime import run_node
from epp_ros.nodes.stopping import shutdown_on_signals
from epp_ros.uwb.emulation import (anchor_lines, anchor_rounds, channel_devices, corrupt,
                                   cycle_lines, PtyOutput, reports_anchor_ranges, TcpOutput)
from epp_ros.uwb.formats import fits_slots, FORMATS
from geometry_msgs.msg import PoseArray
import numpy as np
from rclpy.node import Node
from rclpy.utilities import remove_ros_args


#: The noise options' defaults (None when parsed: --field refuses them when given).
NOISE_DEFAULTS = {'sigma': 0.05, 'nlos': 0.0, 'drop': 0.0}

#: Metres: mean NLOS excess of --nlos.
NLOS_GAMMA = 2.0

#: Seconds of motion played forth and back, so that the boom never jumps.
PLAYBACK_S = 600.0


def parse_args(argv):
    parser = Parser(prog='uwb_emulator',
                    description=__doc__.lstrip().splitlines()[0])
    parser.add_argument('--protocol', choices=list(FORMATS), default='json')
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument('--pty', action='store_true', help='serve on pseudo-terminal(s)')
    where.add_argument('--tcp', metavar='HOST:PORT', type=host_port,
                       help='serve as TCP bridge(s) (per-tag channels on PORT, PORT+1, ...)')
    parser.add_argument('--link', help='symlink to the (first) pty, e.g. /tmp/ttyUWB; '
                                       'further channels get .1, .2, ...')
    parser.add_argument('--no-newline', action='store_true',
                        help='write messages back to back without line ends, as the '
                             'Makerfabs ESP32 UWB tag writes its JSON')
    parser.add_argument('--config', help='pump description (default: the packaged pump.yaml)')
    parser.add_argument('--rate', type=RATE_HZ, default=10.0,
                        help='ranging cycles per second')
    parser.add_argument('--sigma', type=NOISE_M,
                        help=f'range noise, metres (default {NOISE_DEFAULTS["sigma"]:g})')
    parser.add_argument('--nlos', type=FRACTION,
                        help='fraction of NLOS links (exponential excess, mean 2 m; '
                             'default 0)')
    parser.add_argument('--drop', type=FRACTION,
                        help='link dropout probability (default 0)')
    add_field_options(parser)
    parser.add_argument('--garbage', type=FRACTION, default=0.0,
                        help='probability that a line is corrupted or noise is sent')
    parser.add_argument('--truth', action='store_true',
                        help='publish the true posture on arm_posture/ground_truth')
    parser.add_argument('--duration', type=DURATION_S, default=None,
                        help='stop after seconds')
    parser.add_argument('--seed', type=SEED, default=0)
    args = parser.parse_args(argv)
    settle_noise_options(parser, args, NOISE_DEFAULTS)
    if args.tcp:
        args.host, args.port = args.tcp
    return args


class ForthAndBack(Motion):
    """A motion played forth and back over ``span`` seconds: endless, and never jumping."""

    def __init__(self, motion, span):
        self.model, self.motion, self.span = motion.model, motion, span

    def angles(self, times):
        """Return the angles of the motion at ``times`` folded into [0, span], seconds."""
        times = np.asarray(times, dtype=float)
        return self.motion.angles(self.span - np.abs(np.mod(times, 2 * self.span) - self.span))


class Measurements:
    """
    What the emulated devices measure: each cycle's tag-anchor ranges, anchor-anchor rounds.

    Parameters
    ----------
    measure : callable
        ``cycle -> (ranges (p, m), joints (p, 3))``, metres.
    simulator : FieldSimulator
        Draws the anchor-anchor rounds, from a stream of its own (the cycles' draws stay).

    """

    def __init__(self, measure, simulator):
        self.measure, self.simulator = measure, simulator

    def __call__(self, cycle):
        """Return the ranges (p, m) and the true joints (p, 3) of ``cycle``, metres."""
        return self.measure(cycle)

    def anchor_ranges(self):
        """Return one round of anchor-anchor ranges (m, m), metres, NaN on the diagonal."""
        return self.simulator.anchor_ranges()


def range_source(args, model, rng, moving_anchors=None):
    """
    Return the emulated devices' :class:`Measurements`: ``cycle -> (ranges, joints)``.

    Cycle n is at ``n / args.rate`` seconds; ``joints`` is the true posture then, metres.
    ``rng`` draws the noise; the motion has its own generator seeded with ``args.seed``.
    Without a field simulator for the ranges (no ``--field``, working motion) the
    anchor-anchor rounds come from a field simulator of the configured anchors with the
    noise options, seeded with ``args.seed``. ``moving_anchors``: the anchors off the truck
    body (``PumpConfig.moving_anchor_indices``), which ``anchors_moved`` moves.
    """
    if args.field is None and args.motion == 'working':
        trajectory = working_cycle(model, PLAYBACK_S, args.rate,
                                   rng=np.random.default_rng(args.seed))
        noise = RangeNoise(sigma=args.sigma, nlos_fraction=args.nlos, nlos_gamma=NLOS_GAMMA,
                           dropout=args.drop)
        count = len(trajectory.times)

        def measure(cycle):
            index = cycle % (2 * count - 2)
            joints = trajectory.joints[index if index < count else 2 * count - 2 - index]
            return noise.apply(model.ranges(joints), rng)[0], joints
        return Measurements(measure, FieldSimulator(model, effects_of(args, moving_anchors),
                                                    np.random.default_rng(args.seed)))
    motion = ForthAndBack(make_motion(args.motion, model, PLAYBACK_S,
                                      np.random.default_rng(args.seed)), PLAYBACK_S)
    simulator = FieldSimulator(model, effects_of(args, moving_anchors), rng,
                               frame_period=1.0 / args.rate)

    def measure(cycle):
        frame = simulator.frame(motion, cycle / args.rate)
        return frame.ranges, frame.joints
    return Measurements(measure, simulator)


def effects_of(args, moving_anchors=None):
    """Return the field effects of ``--field`` or the noise options (``arguments``)."""
    return field_effects_of(args, NLOS_GAMMA, moving_anchors)


def open_outputs(args, config):
    """
    Open the channels for this protocol; return them and the lines announcing them.

    Each announcement is ``PTY <path>`` or ``TCP <url>``, followed by the tag id and the
    anchor id that the channel's lines do not name, where the format names none.
    """
    outputs, announcements = [], []
    for channel, devices in enumerate(channel_devices(args.protocol, config)):
        suffix = '' if channel == 0 else f'.{channel}'
        if args.pty:
            output = PtyOutput(link=args.link + suffix if args.link else None)
            kind = 'PTY'
        else:
            output = TcpOutput(args.host, args.port + channel if args.port else 0)
            kind = 'TCP'
        outputs.append(output)
        announcements.append(' '.join([kind, output.path, *(d for d in devices if d)]))
    return outputs, announcements


def close_outputs(outputs):
    """Close and forget each output: a pty closed twice could close a reused descriptor."""
    while outputs:
        outputs.pop().close()


class UwbEmulator(Node):
    """Writes one cycle of device lines per timer tick."""

    node_name = 'uwb_emulator'

    def __init__(self, args, config, outputs):
        super().__init__(self.node_name)
        self.args, self.config, self.outputs = args, config, outputs
        self.model = config.model()
        self.rng = np.random.default_rng(args.seed)
        self.measure = range_source(args, self.model, self.rng, config.moving_anchor_indices)
        self.reports_anchor_ranges = reports_anchor_ranges(args.protocol)
        self.truth = (self.create_publisher(PoseArray, contract.TRUTH.name, TRUTH_QOS)
                      if args.truth else None)
        self.cycle = 0
        # Taken at the first cycle: with use_sim_time the clock reads 0 until /clock comes.
        self.started = None
        self.create_timer(1.0 / args.rate, self.step)

    def step(self):
        now = self.get_clock().now()
        if self.started is None:
            self.started = now
        if self.args.duration is not None and \
                (now - self.started).nanoseconds * 1e-9 >= self.args.duration:
            raise SystemExit(0)
        ranges, joints = self.measure(self.cycle)
        stamp = now.to_msg()
        ending = '' if self.args.no_newline else '\r\n'
        for channel, line in self._anchor_lines() + cycle_lines(
                self.config, ranges, self.args.protocol, self.cycle):
            data = (line + ending).encode()
            if self.rng.random() < self.args.garbage:
                data = corrupt(line, self.rng) + ending.encode()
            self.outputs[channel].write(data)
        if self.truth is not None:
            self.truth.publish(posture_message(self.model.pivot_of(joints), joints, stamp,
                                               self.config.frame_id))
        self.cycle += 1

    def _anchor_lines(self):
        """Return this cycle's anchor-anchor lines (the start-up burst, then one a second)."""
        if not self.reports_anchor_ranges:
            return []
        lines = []
        for _ in range(anchor_rounds(self.cycle, self.args.rate)):
            lines += anchor_lines(self.config, self.measure.anchor_ranges(),
                                  self.args.protocol, self.cycle)
        return lines

    def close(self):
        """Close the outputs, each once (``main`` closes what is left)."""
        close_outputs(self.outputs)


def main(argv=None):
    # First: a Ctrl-C while the outputs open must not end in a traceback either.
    shutdown_on_signals()
    argv = sys.argv if argv is None else argv
    args = parse_args(remove_ros_args(argv)[1:])
    try:
        config = load_pump_config(args.config)
    except ConfigError as exc:
        print(f'uwb_emulator: bad pump configuration: {exc}', file=sys.stderr)
        return 2
    slots = FORMATS[args.protocol].anchor_slots
    if slots is not None and not all(fits_slots(a, slots) for a in config.anchor_ids):
        print(f'uwb_emulator: anchor_ids: the {args.protocol} format carries anchors '
              f'0-{slots - 1} only, the configuration has {list(config.anchor_ids)}',
              file=sys.stderr)
        return 2
    try:
        outputs, announcements = open_outputs(args, config)
    except OSError as exc:
        print(f'uwb_emulator: cannot open the output: {exc}', file=sys.stderr)
        return 2
    print('\n'.join(announcements), flush=True)
    try:
        return run_node(lambda: UwbEmulator(args, config, outputs), argv,
                        name=UwbEmulator.node_name)
    finally:
        close_outputs(outputs)


if __name__ == '__main__':
    sys.exit(main())
