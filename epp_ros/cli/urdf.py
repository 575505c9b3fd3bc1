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
epp_urdf: the URDF of a pump description, for robot_state_publisher, RViz and MoveIt.

    epp_urdf [pump.yaml] [--max-angular-rate RAD_PER_S] [-o boom.urdf]

Writes the URDF the posture estimator publishes on ``robot_description``: a revolute slew
joint, one revolute joint per section, the tags and anchors as fixed frames
(epp_ros.app.robot_description). Without a file, the packaged pump.yaml; without -o, stdout.
The joints' velocity limit is the estimator's max_angular_rate as the file sets it, as the
estimator started with it reads it. A description that cannot be read is one line and exit
status 2.
"""
import argparse
import sys

from epp_ros.app.settings import SETTINGS
from epp_ros.cli.arguments import number, Parser


def parse_args(argv):
    parser = Parser(prog='epp_urdf', description=__doc__.lstrip().splitlines()[0],
                    epilog=__doc__.lstrip().split('\n', 2)[2],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('config', nargs='?', help='pump description (default: the packaged '
                                                  'pump.yaml)')
    rate = SETTINGS['max_angular_rate']
    parser.add_argument('--max-angular-rate', type=number(rate.low, rate.high),
                        metavar='RAD_PER_S', help="every joint's velocity limit (default: the "
                                                  f"file's max_angular_rate, else {rate.default})")
    parser.add_argument('-o', '--output', help='write here instead of stdout')
    return parser.parse_args(argv)


def configured_rate(path):
    """Return the estimator's max_angular_rate in a pump.yaml, as the estimator reads it."""
    from epp_ros.app.config import ConfigError, read_parameters
    from epp_ros.app.settings import file_settings
    try:
        return file_settings(read_parameters(path), ['max_angular_rate'])['max_angular_rate']
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def main(argv=None):
    """Run ``epp_urdf``; return the exit status."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    from epp_ros.app.config import ConfigError, load_pump_config
    from epp_ros.app.robot_description import urdf
    try:
        config = load_pump_config(args.config)
        rate = args.max_angular_rate or configured_rate(args.config)
        text = urdf(config, rate)
        if args.output is None:
            sys.stdout.write(text)
        else:
            with open(args.output, 'w') as out:
                out.write(text)
    except ConfigError as exc:
        print(f'epp_urdf: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(f'epp_urdf: {args.output}: {exc.strerror or exc}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
