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
uwb_driver: UWB range lines from serial ports, WiFi bridges and WiFi tags -> /uwb/ranges.

Publishes ``sensor_msgs/JointState`` on ``uwb/ranges`` (relative: namespaces work), one
message per ranging cycle, as a stamped, labelled range array: ``name[i] = "<tag>:<anchor>"``
(config names), ``position[i]`` the range in metres or NaN where the pair did not report this
cycle, then ``"<tag>:<tag>"`` for each tag-tag range reported this cycle (a record whose
anchor id is another configured tag's), ``header.stamp`` the receive time of the newest
range, ``effort[i]`` how long before the stamp range i was received (s, NaN where missing),
``velocity`` empty, and last the frame's number (``"frame"``: 1, 2, 3, ... since the
driver started, as its diagnostics' ``frames`` count them), from which a receiver counts
what it lost (``epp_ros.app.contract``). It never publishes on ``joint_states``.
Anchor-anchor ranges (TREK1000 ``ma`` lines) go to ``uwb/anchor_ranges``, one message per
line: ``name[i] = "<anchor>:<anchor>"`` (measuring anchor first), ``position[i]`` metres,
stamped with the line's receive time; implausible ones and unknown anchors are dropped and
counted. Diagnostics at 1 Hz on ``/diagnostics``. Stamps, frame timing and ages are read
from the node's clock, so ``use_sim_time`` (with ``/clock``) is followed; lines read on
simulated time before the first ``/clock`` have no time to be stamped with, and are dropped
and counted (``dropped before /clock``).
"""
import functools
import sys
import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from epp_ros.app import contract
from epp_ros.app.config import ConfigError, listen_address, normalise_device_id, PROTOCOLS, Source
from epp_ros.nodes.messages import qos, RANGES_QOS, to_time
from epp_ros.nodes.parameters import declare, declare_pump_parameters, pump_id
from epp_ros.nodes.runtime import run_node, StartupError
from epp_ros.uwb.decoder import PeerDecoders
from epp_ros.uwb.formats import anchor_slot_problem
from epp_ros.uwb.frames import FrameAssembler, MAX_RANGE, MIN_RANGE
from epp_ros.uwb.source import open_source
from rclpy.node import Node
from sensor_msgs.msg import JointState


class UwbDriver(Node):
    """Reads every configured source and publishes one range frame per cycle."""

    node_name = 'uwb_driver'

    def __init__(self):
        super().__init__(self.node_name)
        self.config = declare_pump_parameters(self)
        # The sources and their framing are opened at start: every setting is read-only.
        fixed = functools.partial(declare, self, read_only=True)
        baud = fixed('baud', 115200, 'Baud rate of serial sources.')
        frame_period = fixed('frame_period', 0.1, 'Longest ranging cycle, s: a frame closes '
                             'when every pair reported or after this long.')
        min_range = fixed('min_range', MIN_RANGE, 'Shortest plausible range, m.')
        max_range = fixed('max_range', MAX_RANGE, 'Longest plausible range, m.')
        max_line = fixed('max_line', 4096, 'Longest line kept, bytes.')
        port = fixed('port', '', 'A single source instead of the configured list.')
        protocol = fixed('protocol', 'auto', f'Protocol of `port`: {PROTOCOLS}.')
        tag = fixed('tag', '', 'Tag id on `port` for formats that do not name it.')
        anchor = fixed('anchor', '', 'Anchor id on `port` for formats that name no device.')
        sources = self.config.sources
        if port:
            sources = (self._single_source(port, protocol, tag, anchor),)
        problem = anchor_slot_problem(self.config.anchor_ids, [s.protocol for s in sources])
        if problem:
            raise StartupError(f'anchor_ids: {problem}')
        try:
            self.assembler = FrameAssembler(self.config, frame_period, min_range, max_range)
        except ValueError as exc:
            raise StartupError(f'frame_period, min_range, max_range: {exc}') from None
        self.publisher = self.create_publisher(JointState, contract.RANGES.name, RANGES_QOS)
        self.anchor_publisher = self.create_publisher(JointState, contract.ANCHOR_RANGES.name,
                                                      qos(contract.ANCHOR_RANGES))
        self.diagnostics = self.create_publisher(DiagnosticArray, contract.DIAGNOSTICS.name,
                                                 contract.DIAGNOSTICS.depth)
        self.link_names = self.config.link_names
        self._lock = threading.Lock()
        self._last_frame = self._now()
        self._previous_counts = {}
        self._newest_line = {}          # port -> node-clock time of its newest line, s
        self._before_clock = 0          # lines read on simulated time before any /clock
        self._closed = False
        self.readers = []
        for source in sources:
            decoders = PeerDecoders(source.protocol)     # each client of a port its own
            reader = open_source(source.port, self._handler(source, decoders), baud=baud,
                                 max_line=max_line, on_closed=decoders.forget)
            self.readers.append((source, decoders, reader))
        for _, _, reader in self.readers:
            reader.start()
        self.create_timer(min(frame_period / 4, 0.05), self._close_stale_frames)
        self.create_timer(1.0, self._publish_diagnostics)
        self.get_logger().info(
            f'reading {", ".join(f"{s.port} ({s.protocol})" for s in sources)}; '
            f'{len(self.link_names)} tag-anchor pairs')

    @staticmethod
    def _single_source(port, protocol, tag, anchor):
        """Return the source given by the ``port`` parameters."""
        if protocol not in PROTOCOLS:
            raise StartupError(f'protocol: {protocol!r} is not one of {list(PROTOCOLS)}')
        try:
            listen_address(port)
        except ConfigError as exc:
            raise StartupError(f'port: {exc}') from None
        return Source(port, protocol, normalise_device_id(tag) or None,
                      normalise_device_id(anchor) or None)

    def _now(self):
        """Return the node's clock, seconds: system time, or simulated time with use_sim_time."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _handler(self, source, decoders):
        def on_line(line, _wall_received, peer):
            # The source stamps lines with wall time; the node's clock is what ROS time is.
            received = self._now()
            if received == 0.0:     # use_sim_time before the first /clock: no time to stamp
                with self._lock:
                    self._before_clock += 1
                return
            self._newest_line[source.port] = received
            decoder = decoders.decoder(peer)
            records = decoder.decode(line)
            if not records:
                return
            line_format = decoder.format
            whole = line_format is not None and line_format.whole_tag
            with self._lock:
                for frame in self.assembler.add_line(records, received, source.tag, whole,
                                                     source.anchor):
                    self._publish(frame)
                self._publish_anchor_ranges(self.assembler.take_anchor_ranges())
        return on_line

    def _close_stale_frames(self):
        with self._lock:
            for frame in self.assembler.poll(self._now()):
                self._publish(frame)

    def _publish(self, frame):
        message = JointState()
        message.header.stamp = to_time(frame.stamp)
        message.header.frame_id = self.config.frame_id
        message.name, message.position, message.effort = contract.frame_fields(frame, self.config)
        self.publisher.publish(message)
        self._last_frame = self._now()

    def _publish_anchor_ranges(self, anchor_round):
        """Publish one line's anchor-anchor ranges on ``uwb/anchor_ranges`` (None: none)."""
        if anchor_round is None:
            return
        message = JointState()
        message.header.stamp = to_time(anchor_round.stamp)
        message.header.frame_id = self.config.frame_id
        message.name, message.position = contract.anchor_round_fields(anchor_round, self.config)
        self.anchor_publisher.publish(message)

    def _publish_diagnostics(self):
        now = self._now()
        array = DiagnosticArray()
        array.header.stamp = to_time(now)
        silent = now - self._last_frame
        with self._lock:
            dropped = dict(self.assembler.dropped)
            frames = self.assembler.frames  # each published, numbered 1, 2, 3, ...
            anchor_ranges = self.assembler.anchor_ranges
            before_clock = self._before_clock
        for source, decoders, reader in self.readers:
            # Named by node (its namespace too), the device by pump and port.
            status = DiagnosticStatus(
                name=f'{self.get_fully_qualified_name().lstrip("/")}: {source.port}',
                hardware_id=f'{pump_id(self, self.config.frame_id)}:{source.port}')
            decoded = decoders.counts
            counts = {'lines': reader.counts['lines'], 'frames': frames}
            rates = {key: (value - self._previous_counts.get((source.port, key), value))
                     for key, value in counts.items()}
            for key, value in counts.items():
                self._previous_counts[(source.port, key)] = value
            if reader.state == 'listening':
                status.level = DiagnosticStatus.WARN
                status.message = f'listening, no device connected {reader.last_error}'.strip()
            elif reader.state != 'connected':
                status.level = DiagnosticStatus.ERROR
                status.message = f'{reader.state}: {reader.last_error}'
            elif silent > 1.0:
                status.level = DiagnosticStatus.WARN
                status.message = f'no frame for {silent:.1f} s'
            else:
                status.level = DiagnosticStatus.OK
                status.message = 'ranging'
            values = {
                'connection': reader.state, 'protocol': decoders.protocol or 'detecting',
                'lines/s': rates['lines'], 'frames/s': rates['frames'],
                'lines': reader.counts['lines'], 'frames': frames,
                'unparsed lines': decoded['unparsed'],
                'parse errors': decoded['errors'],
                'position lines': decoded['position'],
                'preamble lines': decoded['preamble'],
                'input backlog (bytes)': reader.backlog,
                'newest line age (s)': ('none' if source.port not in self._newest_line
                                        else f'{now - self._newest_line[source.port]:.3f}'),
                'clients': reader.clients,
                'connections': reader.counts['connections'],
                'clients closed idle': reader.counts['idle_closed'],
                'clients evicted by a newcomer': reader.counts['evicted'],
                'dropped implausible': dropped.get('implausible', 0),
                'dropped unknown device': dropped.get('unknown_tag', 0)
                + dropped.get('unknown_anchor', 0),
                'dropped without tag': dropped.get('no_tag', 0),
                'dropped without anchor': dropped.get('no_anchor', 0)
                + dropped.get('anchor_range', 0),
                'anchor-anchor ranges published': anchor_ranges,
                'dropped before /clock': before_clock,
                'raw ranges (corrected ones used)': dropped.get('raw_range', 0),
                'overlong lines': reader.overlong,
                'reconnects': reader.counts['reconnects'],
                'io errors': reader.counts['io_errors'],
                'handler errors': reader.counts['handler_errors'],
                'last error': reader.last_error,
            }
            status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
            array.status.append(status)
        self.diagnostics.publish(array)

    def close(self):
        """Stop every reader, once: ``run_node`` may call it again while shutting down."""
        if self._closed:
            return
        self._closed = True
        for _, _, reader in self.readers:
            reader.stop()


def main(args=None):
    return run_node(UwbDriver, args)


if __name__ == '__main__':
    sys.exit(main())
