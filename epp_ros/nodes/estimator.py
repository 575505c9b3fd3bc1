"""posture_estimator: uwb/ranges -> arm_posture, every frame, with diagnostics and markers.

Subscribes to ``uwb/ranges`` (``sensor_msgs/JointState`` from uwb_driver; reliable, keep
all, so no frame is lost silently: a node that lags shows it as latency), arranges the
``"<tag>:<anchor>"`` ranges as the configured (p, m) matrix (and ``"<tag>:<tag>"`` ones as
tag-tag ranges) and runs :class:`epp_ros.core.PostureEstimator`, warm-started from the
previous pose. With a method that fuses angle sensors (chain), it also subscribes to
``boom_angles`` (``sensor_msgs/JointState``: slew encoder and inclinometers, radians) and
gives each frame the newest angles within ``angle_max_age`` of its stamp. Publishes, with
the range frame's stamp:

- ``arm_posture`` (``geometry_msgs/PoseArray``): the base pivot, then joints 1..p; pose k's
  x-axis along section k, z-axis up in the boom's vertical plane;
- ``arm_posture/markers`` (``visualization_msgs/MarkerArray``) for RViz;
- ``/diagnostics`` at 1 Hz: section lengths and errors, range residual, iterations, solve
  time, missing links, counters; level: the worst frame's since the last report (from the
  thresholds), STALE when no frame came for 1 s.

A frame that cannot be solved publishes no pose; after ``reset_after_failures`` such frames
in a row the estimator starts cold. Frames whose stamp is not newer than the last one are
ignored and counted; a stamp more than 1 s older than the last is taken as a clock jump and
the estimator starts over. Topic names are relative: ``-r __ns:=/pump7`` runs one per pump.
"""
import math
import sys
import time
from collections import Counter

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from epp_ros.angles import AngleSamples
from epp_ros.core import METHODS, RANGE_METHODS, PostureEstimator
from epp_ros.core.estimators import accepted_options
from epp_ros.core.nlos import NlosMixture
from epp_ros.health import Thresholds, assess, grade
from epp_ros.nodes.common import (POSTURE_QOS, RANGES_INPUT_QOS, StartupError, declare,
                                  declare_pump_parameters, posture_message, posture_markers,
                                  run_node, to_seconds, to_time)

BACKWARD_JUMP = 1.0      # s: an older stamp by more than this is a clock jump, not disorder
LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}


class PostureEstimatorNode(Node):
    """Solves every range frame for the boom's posture."""

    node_name = 'posture_estimator'

    def __init__(self):
        super().__init__(self.node_name)
        self.config = declare_pump_parameters(self)
        method = declare(self, 'method', 'cepp', f'Estimator: {", ".join(RANGE_METHODS)}.')
        if method not in RANGE_METHODS:
            raise StartupError(f'method: {method!r} is not one of {RANGE_METHODS} (the node '
                               'receives UWB ranges only)')
        self.reset_after = declare(self, 'reset_after_failures', 10,
                                   'Unsolvable frames in a row before a cold start.')
        self.thresholds = Thresholds(
            declare(self, 'arm_length_warn', 0.05, 'Section length error for WARN, m.'),
            declare(self, 'arm_length_error', 0.5, 'Section length error for ERROR, m.'),
            declare(self, 'residual_warn', 0.5, 'Range residual RMS for WARN, m.'),
            declare(self, 'residual_error', 2.0, 'Range residual RMS for ERROR, m.'))
        self.publish_markers = declare(self, 'publish_markers', True,
                                       'Also publish arm_posture/markers for RViz.')
        if self.reset_after < 1:
            raise StartupError('reset_after_failures: must be >= 1')
        noise = {'sigma': declare(self, 'range_sigma', 0.1,
                                  'UWB range standard deviation, m (methods that weigh it).'),
                 'nlos_fraction': declare(self, 'nlos_fraction', 0.1,
                                          'Prior probability that a range is NLOS (chain).'),
                 'nlos_gamma': declare(self, 'nlos_gamma', 1.0, 'Mean NLOS excess, m (chain).'),
                 'tag_sigma': declare(self, 'tag_sigma', 0.1,
                                      'Tag-tag range standard deviation, m (chain).'),
                 'pitch_sigma': declare(self, 'pitch_sigma', math.radians(0.5),
                                        'Inclinometer standard deviation, rad (chain).'),
                 'slew_sigma': declare(self, 'slew_sigma', math.radians(0.5),
                                       'Slew encoder standard deviation, rad (chain).')}
        for name, parameter in (('sigma', 'range_sigma'), ('tag_sigma', 'tag_sigma'),
                                ('pitch_sigma', 'pitch_sigma'), ('slew_sigma', 'slew_sigma')):
            if not noise[name] > 0:
                raise StartupError(f'{parameter}: must be > 0, got {noise[name]}')
        try:
            NlosMixture(noise['nlos_fraction'], noise['nlos_gamma'])   # checked for every method
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.model = self.config.model()
        try:
            self.estimator = PostureEstimator(self.model, method, **{
                name: value for name, value in noise.items()
                if name in accepted_options(method)})
        except ImportError as exc:
            raise StartupError(f'method: {exc}') from None
        self.angles = self._angle_input(method)
        self.lengths = self.model.arm_lengths
        self.posture = self.create_publisher(PoseArray, 'arm_posture', POSTURE_QOS)
        self.markers = self.create_publisher(MarkerArray, 'arm_posture/markers', POSTURE_QOS)
        self.diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'uwb/ranges', self.on_ranges, RANGES_INPUT_QOS)
        if self.angles is not None:
            self.create_subscription(JointState, 'boom_angles', self.on_angles,
                                     RANGES_INPUT_QOS)
        self.create_timer(1.0, self.publish_diagnostics)
        self.counts = Counter()
        self.failures_in_a_row = 0
        self.last_stamp = None
        self.last_frame_time = None
        self.worst = None               # worst (level, message) since the last report
        self.status_name = f'{self.get_fully_qualified_name()}'
        self.get_logger().info(f'{method} on {self.model.n_sections} sections, '
                               f'{self.model.n_anchors} anchors'
                               + (', with boom_angles' if self.angles is not None else ''))

    def _angle_input(self, method):
        """Angle sensors for a method that fuses them (else None); their names and age."""
        if 'pitches' not in METHODS[method].inputs:
            return None
        p = self.model.n_sections
        slew_name = declare(self, 'slew_name', 'slew',
                            'boom_angles joint name of the slew encoder.')
        pitch_names = declare(self, 'pitch_names', [f'pitch{k}' for k in range(1, p + 1)],
                              'boom_angles joint names of the inclinometers, base outward.')
        max_age = declare(self, 'angle_max_age', 0.2,
                          'Largest stamp difference between a range frame and its angles, s.')
        if len(pitch_names) != p:
            raise StartupError(f'pitch_names: needs one name per section ({p}), '
                               f'got {list(pitch_names)}')
        try:
            return AngleSamples(slew_name, pitch_names, max_age)
        except ValueError as exc:
            raise StartupError(str(exc)) from None

    def on_angles(self, message):
        self.angles.add(to_seconds(message.header.stamp), message.name, message.position)

    def on_ranges(self, message):
        try:
            self._on_ranges(message)
        except Exception as exc:  # noqa: BLE001 - one bad frame must not stop the node
            self.counts['errors'] += 1
            self.estimator.reset()
            self.get_logger().error(f'frame dropped: {exc!r}', throttle_duration_sec=5.0)

    def _on_ranges(self, message):
        self.counts['frames'] += 1
        stamp = to_seconds(message.header.stamp)
        if self.last_stamp is not None and stamp <= self.last_stamp:
            if self.last_stamp - stamp < BACKWARD_JUMP:
                self.counts['out_of_order'] += 1
                return
            # The clock jumped back (NTP, a restarted driver, a looping bag): start over.
            self.counts['clock_jumps'] += 1
            self.estimator.reset()
        try:
            ranges, tag_ranges, unknown = self.config.link_matrices(message.name,
                                                                    message.position)
        except ValueError:
            self.counts['malformed'] += 1
            return
        self.counts['unknown_links'] += unknown
        self.last_stamp = stamp
        self.last_frame_time = time.monotonic()
        slew, pitches = (None, None) if self.angles is None else self.angles.at(stamp)
        joints = self.estimator.update(ranges, tag_ranges=tag_ranges, pitches=pitches,
                                       slew=slew)
        level, summary = grade(self.estimator.last_diagnostics, self.thresholds, self.lengths)
        if self.worst is None or level > self.worst[0]:
            self.worst = (level, summary)
        if not self.estimator.last_diagnostics['valid']:
            self.counts['unsolved'] += 1
            self.failures_in_a_row += 1
            if self.failures_in_a_row >= self.reset_after:
                self.estimator.reset()
                self.counts['cold_restarts'] += 1
                self.failures_in_a_row = 0
            return
        self.failures_in_a_row = 0
        self.counts['published'] += 1
        frame_id = message.header.frame_id or self.config.frame_id
        stamp = message.header.stamp                 # the frame's, exactly
        pivot = self.model.pivot_of(joints)
        self.posture.publish(posture_message(pivot, joints, stamp, frame_id))
        if self.publish_markers:
            self.markers.publish(posture_markers(pivot, joints, stamp, frame_id))

    def publish_diagnostics(self):
        diagnostics = self.estimator.last_diagnostics
        status = DiagnosticStatus(name=f'posture_estimator: {self.status_name}',
                                  hardware_id=self.config.frame_id)
        silent = (None if self.last_frame_time is None
                  else time.monotonic() - self.last_frame_time)
        if not diagnostics:
            status.level, status.message = DiagnosticStatus.WARN, 'waiting for uwb/ranges'
            values = {'method': self.estimator.method}
        else:
            level, message, values = assess(diagnostics, self.thresholds, self.lengths)
            if silent > 1.0:
                status.level = DiagnosticStatus.STALE
                status.message = f'no uwb/ranges for {silent:.1f} s'
            else:                           # the worst frame since the last report
                level, status.message = self.worst or (level, message)
                status.level = LEVELS[level]
        self.worst = None
        values.update({f'frames {key}': str(value) for key, value in self.counts.items()})
        if self.angles is not None:
            values.update({f'boom_angles {key}': str(value)
                           for key, value in self.angles.counts.items()})
        status.values = [KeyValue(key=key, value=value) for key, value in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = to_time(time.time())
        self.diagnostics.publish(array)


def main(args=None):
    return run_node(PostureEstimatorNode, args)


if __name__ == '__main__':
    sys.exit(main())
