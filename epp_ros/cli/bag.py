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
epp_bag: synthesise, record, replay, evaluate and describe rosbag2 files.

    epp_bag synth OUT [--storage mcap|sqlite3] [--duration S] [--sigma M] [--nlos F]
                      [--drop F] [--field NAMES] [--motion working|joystick] [--seed N]
                      [--config FILE] [--raw PROTOCOL] [--start S] [--anchor-ranges]
    epp_bag record OUT [--topics T ...] [--duration S] [--storage ...]
    epp_bag play BAG [--rate R] [--loop] [--fast] [--topics T ...] [--clock [HZ]]
    epp_bag eval BAG [--method M] [--config FILE] [--out BAG] [--plot FILE.png] [--json]
    epp_bag info BAG
    epp_bag reindex BAG

A bag that cannot be used (missing, truncated, without the topic, another message type)
gives one error line and exit status 2. eval reads the estimator's settings from --config
(the packaged pump.yaml by default) as posture_estimator does (epp_ros.app.settings); --method
replaces the file's method.

synth draws each cycle's ranges with ``--sigma``/``--nlos``/``--drop`` noise; with
``--field NAMES`` (comma-separated presets of ``epp_ros.core.simulation.FIELD_EFFECTS``) or
``--motion joystick`` from ``epp_ros.core.simulation.simulate.FieldSimulator`` instead, with the
presets' effects or, without ``--field``, the same noise. ``--field`` replaces the noise
options: giving both is refused. ``--anchor-ranges`` (field simulator too) also writes
``/uwb/anchor_ranges``: rounds of every anchor's ranges to every other
(``FieldSimulator.anchor_ranges``: the true, possibly displaced anchors, their offsets, the
range noise), a burst at start-up and one round a second, as the emulator prints them
(``epp_ros.uwb.emulation.anchor_rounds``); with ``--raw`` their lines too, where the format
has them. ``record`` records ``/uwb/anchor_ranges`` by default; it opens OUT before it
subscribes (an OUT that exists or cannot be written is refused at once) and writes every
message as it arrives, so a long recording holds no more in memory than a short one.
A recorder that was killed leaves no metadata.yaml: ``reindex`` makes its bag readable up
to the last chunk it wrote (a chunk a MiB, as ``ros2 bag reindex``).
"""
import argparse
import importlib
import json
import signal
import sys
import time

from epp_ros.app import bags, contract
from epp_ros.app.config import ConfigError, load_pump_config
from epp_ros.app.settings import estimator_options
from epp_ros.app.threads import single_blas_thread
from epp_ros.cli.arguments import (add_field_options, field_effects_of, integer, number, Parser,
                                   settle_noise_options)
from epp_ros.core import RANGE_METHODS
from epp_ros.core.simulation import FieldSimulator, make_motion
from epp_ros.uwb.emulation import anchor_rounds
from epp_ros.uwb.formats import FORMATS
import numpy as np

DEFAULT_RECORD = [bags.RANGES, bags.ANCHOR_RANGES, bags.POSTURE, bags.TRUTH,
                  contract.DIAGNOSTICS.absolute]
CLOCK_HZ = 40.0         # /clock rate of `play --clock`, as ros2 bag play's default
CLOCK_TOPIC = '/clock'
#: synth's noise options' defaults (None when parsed: --field refuses them when given).
NOISE_DEFAULTS = {'sigma': 0.1, 'nlos': 0.0, 'drop': 0.0}
NLOS_GAMMA = 2.0        # metres, mean NLOS excess of --nlos, as bags.synthesize's


def parse_args(argv):
    parser = Parser(prog='epp_bag', description=__doc__.lstrip().splitlines()[0],
                    epilog=__doc__.lstrip().split('\n', 2)[2],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest='command', required=True)
    synth = commands.add_parser('synth', help='write a simulated working cycle')
    synth.add_argument('out')
    synth.add_argument('--storage', choices=sorted(bags.STORAGES), default='mcap')
    synth.add_argument('--duration', type=number(0, 86400, low_open=True), default=60.0)
    synth.add_argument('--rate', type=number(0, 1000, low_open=True), default=10.0)
    synth.add_argument('--sigma', type=number(0, 100),
                       help=f'range noise, metres (default {NOISE_DEFAULTS["sigma"]:g})')
    synth.add_argument('--nlos', type=number(0, 1),
                       help=f'fraction of NLOS links (exponential excess, mean {NLOS_GAMMA:g} '
                            'm; default 0)')
    synth.add_argument('--drop', type=number(0, 1), help='link dropout probability (default 0)')
    add_field_options(synth)
    synth.add_argument('--seed', type=integer(0, 2 ** 63 - 1), default=0)
    synth.add_argument('--config')
    synth.add_argument('--raw', choices=list(FORMATS),
                       help='also write the device lines on /uwb/raw')
    synth.add_argument('--start', type=number(0, 1e10, low_open=True), metavar='S',
                       help='time of the first message, seconds since the epoch (default: '
                            'now); e.g. 1000 for a bag that is plainly simulated time')
    synth.add_argument('--anchor-ranges', action='store_true',
                       help='also write /uwb/anchor_ranges from the field simulator: a '
                            'start-up burst, then one round a second (for the anchor '
                            'self-survey of epp_calibrate)')
    record = commands.add_parser('record', help='record topics until Ctrl-C or --duration')
    record.add_argument('out')
    record.add_argument('--topics', nargs='+', default=DEFAULT_RECORD)
    record.add_argument('--duration', type=number(0, 1e7, low_open=True))
    record.add_argument('--storage', choices=sorted(bags.STORAGES), default='mcap')
    play = commands.add_parser('play', help='publish a bag with its recorded timing')
    play.add_argument('bag')
    play.add_argument('--rate', type=number(0, 1000, low_open=True), default=1.0,
                      help='speed factor')
    play.add_argument('--loop', action='store_true')
    play.add_argument('--fast', action='store_true',
                      help='as fast as the subscribers keep up (reliable, nothing lost)')
    play.add_argument('--topics', nargs='+')
    play.add_argument('--salvage', action='store_true',
                      help='play what can be read of a damaged bag (default: refuse it)')
    play.add_argument('--clock', type=number(0, 10000, low_open=True), nargs='?',
                      const=CLOCK_HZ, metavar='HZ',
                      help="also publish the bag's time on /clock (rosgraph_msgs/Clock), "
                           f'at HZ (default {CLOCK_HZ:g}) and with every message, for nodes '
                           'started with use_sim_time:=true; a /clock in the bag is then '
                           'not played')
    play.add_argument('--subscribers', type=integer(1, 1000), metavar='N',
                      help='wait up to 10 s until every topic has N subscribers (without: '
                           'up to 2 s for one)')
    evaluate = commands.add_parser('eval', help='run an estimator offline over a bag')
    evaluate.add_argument('bag')
    evaluate.add_argument('--method', choices=RANGE_METHODS,
                          help="instead of the config's method")
    evaluate.add_argument('--config', help='the pump.yaml: its pump and the estimator '
                                           'settings, as posture_estimator reads them '
                                           '(default: the packaged one)')
    evaluate.add_argument('--out', help='write a copy with /arm_posture added')
    evaluate.add_argument('--plot', help='PNG of the error over time')
    evaluate.add_argument('--json', action='store_true')
    evaluate.add_argument('--salvage', action='store_true',
                          help='evaluate what can be read of a damaged bag (default: refuse)')
    show = commands.add_parser('info', help='topics, counts, duration')
    show.add_argument('bag')
    repair = commands.add_parser('reindex', help='recover a bag whose recorder was killed, '
                                                 'up to its last whole chunk')
    repair.add_argument('bag')
    args = parser.parse_args(argv)
    if args.command == 'synth':
        settle_noise_options(synth, args, NOISE_DEFAULTS)
    return args


def run_synth(args):
    config = load_pump_config(args.config)
    start_ns = time.time_ns() if args.start is None else int(round(args.start * 1e9))
    if args.field or args.motion != 'working' or args.anchor_ranges:
        counts = synthesize_field(args, config, start_ns)
    else:
        counts = bags.synthesize(args.out, config, args.duration, args.rate, args.sigma,
                                 args.nlos, args.drop, args.seed, args.storage, args.raw,
                                 start_ns=start_ns)
    print(f'wrote {args.out}: ' + ', '.join(f'{t} {n}' for t, n in counts.items()))


def synthesize_field(args, config, start_ns):
    """
    Write a field simulation as a bag, with the topics and stamps of ``bags.synthesize``.

    One generator seeded with ``--seed`` draws the motion (a working cycle the same as
    ``bags.synthesize``'s), then the field. Every cycle gives ``/uwb/ranges``, with each
    range's measurement time (TDMA slots) as its age, and the true posture at its stamp on
    ``/arm_posture/ground_truth`` (and, with ``--raw``, the devices' lines on ``/uwb/raw``);
    with ``--anchor-ranges`` the cycles of :func:`epp_ros.uwb.emulation.anchor_rounds` are
    preceded by rounds of anchor-anchor ranges on ``/uwb/anchor_ranges``, drawn from the
    simulator's own stream (the cycles' draws stay as they are without them).

    Returns
    -------
    dict
        Messages written per topic.

    """
    model = config.model()
    rng = np.random.default_rng(args.seed)
    motion = make_motion(args.motion, model, args.duration, rng)
    effects = field_effects_of(args, NLOS_GAMMA, config.moving_anchor_indices)
    simulator = FieldSimulator(model, effects, rng, frame_period=1.0 / args.rate)

    def cycles():
        for cycle in range(int(round(args.duration * args.rate))):
            frame = simulator.frame(motion, cycle / args.rate)
            ages = np.broadcast_to((frame.stamp - frame.range_stamps)[:, None],
                                   frame.ranges.shape)
            yield (start_ns + int(round(frame.stamp * 1e9)), frame.ranges, frame.joints,
                   np.where(np.isfinite(frame.ranges), ages, np.nan))

    def rounds(cycle):
        return [simulator.anchor_ranges() for _ in range(anchor_rounds(cycle, args.rate))]

    return bags.write_cycles(args.out, config, cycles(), args.storage, args.raw,
                             rounds if args.anchor_ranges else None)


def run_info(args):
    summary = bags.info(args.bag)
    print(f'Bag:       {summary["path"]}\nStorage:   {summary["storage"]}\n'
          f'Duration:  {summary["duration_s"]:.3f} s\nMessages:  {summary["messages"]}')
    for topic in summary['topics']:
        print(f'Topic: {topic["topic"]} | Type: {topic["type"]} | Count: {topic["count"]}')


def run_reindex(args):
    counts, lost_bytes, stopped = bags.reindex(args.bag)
    found = ', '.join(f'{topic} {count}' for topic, count in sorted(counts.items())) or \
        'no messages'
    print(f'reindexed {args.bag}: {found}; {lost_bytes} bytes of an unfinished chunk '
          'dropped')
    if stopped:
        print(f'epp_bag: {args.bag}: reading stopped at a damaged chunk ({stopped}): what '
              'followed it is lost', file=sys.stderr)


def run_eval(args):
    config = load_pump_config(args.config)
    options = estimator_options(args.config, args.method)
    result = bags.evaluate(args.bag, config, options.pop('method'), out=args.out,
                           salvage=args.salvage, **options)
    if result['damage']:
        print(f'epp_bag: salvaged {args.bag}: {result["damage"]}', file=sys.stderr)
    joints = ' '.join(f'{e:.3f}' for e in result['joint_rmse_m']) or '-'
    rejected = ', '.join(f'{count} {reason}' for reason, count
                         in sorted(result['rejected'].items())) or 'none'
    print(f'{args.bag}: {result["frames"]} frames, {result["solved"]} published by '
          f'{result["method"]} (not published: {rejected}); RMSE {result["rmse_m"]:.3f} m '
          f'(per joint {joints}); max arm-length error '
          f'{result["max_arm_length_error_m"]:.2e} m; {result["ms_per_frame"]:.2f} ms/frame')
    if args.plot and result['stamps_ns']:
        import matplotlib
        matplotlib.use('Agg')
        from matplotlib import pyplot
        seconds = (np.array(result['stamps_ns']) - result['stamps_ns'][0]) / 1e9
        figure, axis = pyplot.subplots(figsize=(8, 3.5))
        axis.plot(seconds, result['frame_rmse_m'])
        axis.set_xlabel('time [s]')
        axis.set_ylabel('frame RMSE [m]')
        axis.set_title(f'{result["method"]}: RMSE {result["rmse_m"]:.3f} m')
        axis.grid(True)
        figure.savefig(args.plot, dpi=100, bbox_inches='tight')
        pyplot.close(figure)
    if args.json:
        print(json.dumps({key: value for key, value in result.items()
                          if key not in ('stamps_ns', 'frame_rmse_m')}))


def _message_class(msgtype):
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def _rclpy_qos(profile, fast):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    if fast:       # flow control: a reliable writer that keeps all blocks, never drops
        return QoSProfile(history=HistoryPolicy.KEEP_ALL,
                          reliability=ReliabilityPolicy.RELIABLE)
    if profile is None:
        return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if profile.history.name == 'KEEP_ALL'
        else HistoryPolicy.KEEP_LAST, depth=max(int(profile.depth), 1),
        reliability=ReliabilityPolicy.BEST_EFFORT if profile.reliability.name == 'BEST_EFFORT'
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if profile.durability.name == 'TRANSIENT_LOCAL' else DurabilityPolicy.VOLATILE)


def run_play(args):
    import rclpy
    messages, damage = bags.read_all(args.bag, salvage=args.salvage, topics=args.topics)
    if not damage.intact:
        print(f'epp_bag: salvaged {args.bag}: {damage.describe()}', file=sys.stderr)
    if not messages:
        raise bags.BagError(f'{args.bag}: nothing to play')
    if args.clock:                  # one clock on /clock: ours, from the bag's time
        own = [m for m in messages if m[0] == CLOCK_TOPIC]
        messages = [m for m in messages if m[0] != CLOCK_TOPIC]
        if own:
            print(f"epp_bag: --clock: the bag's own {CLOCK_TOPIC} ({len(own)} messages, "
                  f'{own[0][1]}) is not played; {CLOCK_TOPIC} follows the bag time',
                  file=sys.stderr)
        if not messages:
            raise bags.BagError(f'{args.bag}: nothing to play but {CLOCK_TOPIC}')
    rclpy.init()
    node = rclpy.create_node('epp_bag_player')
    publishers = {}
    for topic, msgtype, _, _, qos in messages:
        if topic not in publishers:
            publishers[topic] = node.create_publisher(_message_class(msgtype), topic,
                                                      _rclpy_qos(qos, args.fast))
    # Created with the others, so that subscribers discover it while we wait for them.
    clock = _Clock(node, args.clock) if args.clock else None
    try:
        # Give subscribers a moment to match, as ros2 bag play does with its delay.
        wanted, patience = (1, 2.0) if args.subscribers is None else (args.subscribers, 10.0)
        deadline = time.monotonic() + patience
        while time.monotonic() < deadline and not (all(
                p.get_subscription_count() >= wanted for p in publishers.values())
                and (clock is None or clock.publisher.get_subscription_count() >= 1)):
            rclpy.spin_once(node, timeout_sec=0.05)
        # Our side has matched; give the subscribers' side a moment to match us too, or the
        # first messages can miss a reader that has not yet discovered this writer.
        settle = time.monotonic() + 0.5
        while time.monotonic() < settle:
            rclpy.spin_once(node, timeout_sec=0.05)
        try:
            while True:
                _play_once(messages, publishers, args, clock)
                if not args.loop:
                    break
            time.sleep(0.5)                 # let the last messages leave
            print(f'played {len(messages)} messages from {args.bag}')
        except KeyboardInterrupt:           # Ctrl-C is how a player is stopped: not an error
            print(f'stopped playing {args.bag}')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


class _Clock:
    """/clock from the bag's time: with every message and at ``hz`` in between."""

    def __init__(self, node, hz):
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        self.message = Clock
        # Best effort, depth 1, as rclpy's TimeSource subscribes (and rosbag2 publishes).
        self.publisher = node.create_publisher(
            Clock, CLOCK_TOPIC,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.period = 1.0 / hz

    def publish(self, t_ns):
        message = self.message()
        message.clock.sec, message.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self.publisher.publish(message)

    def sleep_until(self, wall, bag_ns, wall_to_bag):
        """Sleep until monotonic ``wall``, publishing the bag's time on the way."""
        while True:
            left = wall - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, self.period))
            self.publish(min(bag_ns, wall_to_bag(time.monotonic())))


def _play_once(messages, publishers, args, clock):
    """Publish the messages once, with the recorded timing unless ``--fast``."""
    start, first = time.monotonic(), messages[0][2]

    def wall_to_bag(wall):
        return first + int((wall - start) * args.rate * 1e9)

    sent = 0
    for topic, _, t_ns, raw, _ in messages:
        if not args.fast:
            due = start + (t_ns - first) / 1e9 / args.rate
            if clock is not None:
                clock.sleep_until(due, t_ns, wall_to_bag)
            elif due > time.monotonic():
                time.sleep(due - time.monotonic())
        if clock is not None:       # the clock reaches a message's time before it arrives
            clock.publish(t_ns)
        publishers[topic].publish(raw)
        sent += 1
        if args.fast and sent % FAST_BATCH == 0:
            _wait_for_acks(publishers)
    _wait_for_acks(publishers)


#: Messages published as fast as possible between waits for every subscriber's ack: a
#: writer whose history filled up would give up on a sample after its blocking time, and
#: one that exits with samples unacknowledged loses them.
FAST_BATCH = 1000


def _wait_for_acks(publishers, timeout=60.0):
    """Wait until every subscriber has acknowledged what was published (or ``timeout``)."""
    from rclpy.duration import Duration
    for publisher in publishers.values():
        publisher.wait_for_all_acked(Duration(seconds=timeout))


#: Seconds at most that epp_bag record takes what is queued after it stops.
DRAIN_S = 1.0


def run_record(args):
    # The output is opened first: a path that exists or cannot be written is refused before
    # anything is recorded, and every message goes to it as it arrives.
    with bags.BagWriter(args.out, args.storage) as bag:
        count, topics = _record(args, bag)
    print(f'recorded {count} messages on {topics} topics to {args.out}')


def _record(args, bag):
    """Record ``args.topics`` into ``bag`` until told to stop; (messages, topics)."""
    import rclpy
    import rclpy.executors
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    rclpy.init()
    node = rclpy.create_node('epp_bag_recorder')
    received = [0]
    subscribed = {}
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE)
    stop = {'now': False}
    signal.signal(signal.SIGINT, lambda *_: stop.update(now=True))
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    start = last_lookup = time.monotonic()
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop['now'] and (args.duration is None
                                   or time.monotonic() - start < args.duration):
            if len(subscribed) < len(args.topics) and time.monotonic() - last_lookup > 0.2:
                last_lookup = time.monotonic()
                for topic, types in node.get_topic_names_and_types():
                    if topic in args.topics and topic not in subscribed:
                        msgtype = types[0]

                        def keep(raw, topic=topic, msgtype=msgtype):
                            bag.write(topic, time.time_ns(), raw, msgtype,
                                      bags.TOPIC_QOS.get(topic))
                            received[0] += 1
                        subscribed[topic] = node.create_subscription(
                            _message_class(msgtype), topic, keep, qos, raw=True)
            executor.spin_once(timeout_sec=0.02)
        # Lose nothing that had arrived: take what is queued, until the topics are quiet
        # or DRAIN_S have passed (topics that keep flowing are never quiet).
        end, quiet_since, count = time.monotonic() + DRAIN_S, time.monotonic(), received[0]
        while time.monotonic() < end and time.monotonic() - quiet_since < 0.3:
            executor.spin_once(timeout_sec=0.01)
            if received[0] != count:
                quiet_since, count = time.monotonic(), received[0]
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return received[0], len(subscribed)


COMMANDS = {'synth': run_synth, 'record': run_record, 'play': run_play, 'eval': run_eval,
            'info': run_info, 'reindex': run_reindex}


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    single_blas_thread()
    try:
        COMMANDS[args.command](args)
    except (bags.BagError, ConfigError) as exc:
        print(f'epp_bag: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
