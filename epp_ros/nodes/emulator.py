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

The boom follows a working cycle; each cycle's noisy ranges are written, in any format of
the registry (:data:`epp_ros.uwb.formats.FORMATS`), to a pseudo-terminal (like a USB-UART)
or to TCP clients (like the ESP8266 WiFi bridge). The first stdout lines say where:
``PTY <device path>`` or ``TCP <url>``, one per channel (formats that do not name the tag
need one channel per tag, formats that name no device one per tag-anchor pair; the ids the
lines leave out follow). With ``--truth`` the true posture is published as
``geometry_msgs/PoseArray`` on ``arm_posture/ground_truth`` (base first, then joints 1..p),
stamped with the node's clock (simulated time with ``use_sim_time``), which also paces the
cycles and measures ``--duration``.
"""
import sys

from epp_ros import contract
from epp_ros.arguments import host_port, integer, number, Parser
from epp_ros.config import ConfigError, load_pump_config
from epp_ros.core.simulate import RangeNoise, working_cycle
from epp_ros.nodes.common import posture_message, POSTURE_QOS, run_node
from epp_ros.nodes.stopping import shutdown_on_signals
from epp_ros.uwb.emulation import channel_devices, corrupt, cycle_lines, PtyOutput, TcpOutput
from epp_ros.uwb.formats import fits_slots, FORMATS
from geometry_msgs.msg import PoseArray
import numpy as np
from rclpy.node import Node
from rclpy.utilities import remove_ros_args


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
    parser.add_argument('--rate', type=number(0, 1000, low_open=True), default=10.0,
                        help='ranging cycles per second')
    parser.add_argument('--sigma', type=number(0, 100), default=0.05,
                        help='range noise, metres')
    parser.add_argument('--nlos', type=number(0, 1), default=0.0,
                        help='fraction of NLOS links (exponential excess, mean 2 m)')
    parser.add_argument('--drop', type=number(0, 1), default=0.0,
                        help='link dropout probability')
    parser.add_argument('--garbage', type=number(0, 1), default=0.0,
                        help='probability that a line is corrupted or noise is sent')
    parser.add_argument('--truth', action='store_true',
                        help='publish the true posture on arm_posture/ground_truth')
    parser.add_argument('--duration', type=number(0, 1e7, low_open=True), default=None,
                        help='stop after seconds')
    parser.add_argument('--seed', type=integer(0, 2 ** 63 - 1), default=0)
    args = parser.parse_args(argv)
    if args.tcp:
        args.host, args.port = args.tcp
    return args


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
        self.trajectory = working_cycle(self.model, 600.0, args.rate,
                                        rng=np.random.default_rng(args.seed))
        self.noise = RangeNoise(sigma=args.sigma, nlos_fraction=args.nlos, nlos_gamma=2.0,
                                dropout=args.drop)
        self.truth = (self.create_publisher(PoseArray, contract.TRUTH.name, POSTURE_QOS)
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
        # Play the cycle forth and back: the boom never jumps.
        count = len(self.trajectory.times)
        index = self.cycle % (2 * count - 2)
        joints = self.trajectory.joints[index if index < count else 2 * count - 2 - index]
        ranges, _ = self.noise.apply(self.model.ranges(joints), self.rng)
        stamp = now.to_msg()
        ending = '' if self.args.no_newline else '\r\n'
        for channel, line in cycle_lines(self.config, ranges, self.args.protocol, self.cycle):
            data = (line + ending).encode()
            if self.rng.random() < self.args.garbage:
                data = corrupt(line, self.rng) + ending.encode()
            self.outputs[channel].write(data)
        if self.truth is not None:
            self.truth.publish(posture_message(self.model.pivot_of(joints), joints, stamp,
                                               self.config.frame_id))
        self.cycle += 1

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
