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
- ``/diagnostics`` at 1 Hz: section lengths and errors, range residual and chi-square,
  predicted uncertainty, iterations, solve time, missing links, counters (frames rejected,
  by reason); level: the worst frame's since the last report, STALE when no frame came for
  1 s.

What is published is the estimator's decision (``core.integrity``): a frame that cannot be
solved, whose residuals the configured noise cannot explain, whose posture it does not
determine, or which puts the boom where it cannot be, publishes no pose and is counted by
reason; after ``reset_after_failures`` frames in a row that could not be solved or did not
fit, the estimator starts cold. Frames whose stamp is not newer than the last one are
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
from epp_ros.core.integrity import IntegrityLimits, Thresholds
from epp_ros.health import assess, grade
from epp_ros.nodes.common import (POSTURE_QOS, RANGES_INPUT_QOS, StartupError, declare,
                                  declare_pump_parameters, posture_message, posture_markers,
                                  run_node, to_seconds, to_time)

BACKWARD_JUMP = 1.0      # s: an older stamp by more than this is a clock jump, not disorder
#: Health thresholds: parameter -> (default, description); metres.
THRESHOLDS = {
    'arm_length_warn': (0.05, 'Section length error for WARN, m.'),
    'arm_length_error': (0.5, 'Section length error for ERROR (not published), m.'),
    'residual_warn': (0.5, 'Range residual RMS for WARN, m.'),
    'residual_error': (2.0, 'Range residual RMS for ERROR (not published), m.'),
    'predicted_rmse_warn': (0.5, 'Predicted RMSE (Cramer-Rao bound) for WARN, m.'),
    'predicted_rmse_error': (2.0, 'Predicted RMSE for ERROR (not published), m.'),
}
#: What the estimator is told about the noise: option -> (parameter, default, description).
NOISE = {
    'sigma': ('range_sigma', 0.1, 'UWB range standard deviation, m.'),
    'nlos_fraction': ('nlos_fraction', 0.1, 'Prior probability that a range is NLOS.'),
    'nlos_gamma': ('nlos_gamma', 1.0, 'Mean NLOS excess, m.'),
    'tag_sigma': ('tag_sigma', 0.1, 'Tag-tag range standard deviation, m.'),
    'pitch_sigma': ('pitch_sigma', math.radians(0.5), 'Inclinometer standard deviation, rad.'),
    'slew_sigma': ('slew_sigma', math.radians(0.5), 'Slew encoder standard deviation, rad.'),
    'lowest_joint': ('lowest_joint', -0.5, 'No joint is below this height, m (ground z = 0).'),
}


def _parameter_name(message):
    """An estimator error names its option; say the node parameter instead."""
    option = message.split(':', 1)[0]
    return message.replace(option, NOISE[option][0], 1) if option in NOISE else message
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
        reset_after = declare(self, 'reset_after_failures', 10,
                              'Frames in a row that cannot be solved or do not fit before the '
                              'estimator starts cold.')
        self.publish_markers = declare(self, 'publish_markers', True,
                                       'Also publish arm_posture/markers for RViz.')
        try:
            thresholds = Thresholds(**{name: declare(self, name, default, description)
                                       for name, (default, description) in THRESHOLDS.items()})
            integrity = IntegrityLimits(max_angular_rate=declare(
                self, 'max_angular_rate', IntegrityLimits.max_angular_rate,
                'Fastest slew or pitch rate of the boom, rad/s: rules out jumps and folds.'))
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        told = {name: declare(self, parameter, default, description)
                for name, (parameter, default, description) in NOISE.items()}
        self.model = self.config.model()
        try:
            self.estimator = PostureEstimator(self.model, method, integrity=integrity,
                                              thresholds=thresholds,
                                              reset_after_failures=reset_after, **told)
        except ImportError as exc:
            raise StartupError(f'method: {exc}') from None
        except ValueError as exc:
            raise StartupError(_parameter_name(str(exc))) from None
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
                                       slew=slew, stamp=stamp)
        diagnostics = self.estimator.last_diagnostics
        level, summary = grade(diagnostics)
        if self.worst is None or level > self.worst[0]:
            self.worst = (level, summary)
        self.counts['cold_restarts'] += diagnostics.get('cold_restart', False)
        self.counts['reacquired'] += diagnostics.get('reacquired', False)
        if not diagnostics['valid']:        # the publishing policy is the estimator's
            self.counts['unsolved'] += 1
            self.counts[f'rejected {diagnostics["status"]}'] += 1
            return
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
            level, message, values = assess(diagnostics, self.lengths)
            if silent > 1.0:
                status.level = DiagnosticStatus.STALE
                status.message = f'no uwb/ranges for {silent:.1f} s'
            else:                           # the worst frame since the last report
                level, status.message = self.worst or (level, message)
                status.level = LEVELS[level]
        self.worst = None
        values.update({f'frames {key}': str(value) for key, value in self.counts.items()
                       if key != 'frames'})
        values['frames received'] = str(self.counts['frames'])
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
