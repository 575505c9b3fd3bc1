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
posture_estimator: uwb/ranges -> arm_posture, every frame, with diagnostics and markers.

Subscribes to ``uwb/ranges`` (``sensor_msgs/JointState`` from uwb_driver; reliable, keep
all, so no frame is lost silently: a node that lags shows it as latency; ``ranges_qos:
sensor_data`` for a best-effort publisher), arranges the
``"<tag>:<anchor>"`` ranges as the configured (p, m) matrix (and ``"<tag>:<tag>"`` ones as
tag-tag ranges) and runs :class:`epp_ros.core.PostureEstimator`, warm-started from the
previous pose. With a method that fuses angle sensors (chain), it also subscribes to
``boom_angles`` (``sensor_msgs/JointState``: slew encoder and inclinometers, radians) and
gives each frame the newest angles within ``angle_max_age`` of its stamp. Publishes, with
the range frame's stamp:

- ``arm_posture`` (``geometry_msgs/PoseArray``): the base pivot, then joints 1..p; pose k's
  x-axis along section k, z-axis up in the boom's vertical plane;
- ``arm_posture/markers`` (``visualization_msgs/MarkerArray``) for RViz;
- ``joint_states`` (``sensor_msgs/JointState``): the posture's joint positions, named as
  the pump's URDF, which goes once to ``robot_description`` (transient local);
- ``/diagnostics`` at 1 Hz: section lengths and errors, range residual and chi-square,
  predicted uncertainty, iterations, solve time, missing links, counters (frames rejected,
  by reason); level: the worst frame's since the last report, ERROR when no frame came for
  1 s (a diagnostic aggregator marks a silent node STALE).

What is published is the estimator's decision (``core.integrity``): a frame that cannot be
solved, whose residuals the configured noise cannot explain, whose posture it does not
determine, or which puts the boom where it cannot be, publishes no pose and is counted by
reason; after ``reset_after_failures`` frames in a row that could not be solved or did not
fit, the estimator starts cold. Which frames are solved at all is ``core.frame_policy``'s:
a stamp not newer than the last is ignored and counted, one more than 1 s older is a clock
jump and the estimator starts over, a zero stamp is malformed. Those steps are
``epp_ros.app.pipeline``'s, which ``epp_bag eval`` takes too. Topic names are relative:
``-r __ns:=/pump7`` runs one per pump.

Parameters (``epp_ros.app.settings.SETTINGS``) are live: a change is checked as at start
(refused with the reason otherwise) and applies from the next frame; a new ``method``
starts cold, which ``/diagnostics`` counts. The pump's description and the angle sensors'
names are read-only. Frames are solved on a thread of the node's own
(:mod:`epp_ros.nodes.worker`), in the order they came, the changes of parameters among
them: the executor answers ``set_parameters`` while a frame is being solved. The 1 Hz
report goes before the frames waiting (``messages waiting`` counts them); as the reader's
keep-all queue did, the worker keeps every frame that came.
"""
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from epp_ros.app.angles import AngleSamples
from epp_ros.app.config import PUMP_PARAMETERS
from epp_ros.app.contract import (ANGLES, DIAGNOSTICS, JOINT_STATES, MARKERS, POSTURE, RANGES,
                                  ROBOT_DESCRIPTION)
from epp_ros.app.health import assess, grade
from epp_ros.app.pipeline import RangePipeline
from epp_ros.app.robot_description import joint_names, joint_positions, urdf
from epp_ros.app.settings import estimator_settings, parameter_name, SETTINGS
from epp_ros.core import compile_fit, METHODS, PostureEstimator
from epp_ros.nodes.messages import (posture_markers, posture_message, POSTURE_QOS, qos,
                                    RANGES_INPUT_PROFILES, RANGES_INPUT_QOS, to_seconds, to_time)
from epp_ros.nodes.parameters import declare, declare_pump_parameters, pump_id
from epp_ros.nodes.runtime import run_node, StartupError
from epp_ros.nodes.worker import Worker
from geometry_msgs.msg import PoseArray
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}
#: Seconds without a frame after which the diagnostics say ERROR (a diagnostic aggregator,
#: not the node, marks a silent node STALE).
SILENT_AFTER = 1.0


def descriptor(setting):
    """Return the ParameterDescriptor keywords of a :class:`~epp_ros.app.settings.Setting`."""
    extra = {'read_only': not setting.live}
    if setting.low is None:
        return extra
    if isinstance(setting.default, int):
        extra['integer_range'] = [IntegerRange(from_value=setting.low, to_value=setting.high,
                                               step=1)]
    else:
        extra['floating_point_range'] = [FloatingPointRange(from_value=float(setting.low),
                                                            to_value=float(setting.high))]
    return extra


class PostureEstimatorNode(Node):
    """Solves every range frame for the boom's posture."""

    node_name = 'posture_estimator'

    def __init__(self, **options):
        """Take rclpy Node's keywords (``namespace``, ``parameter_overrides``, ...)."""
        super().__init__(self.node_name, **options)
        self.config = declare_pump_parameters(self)
        self.model = self.config.model()
        self.lengths = self.model.arm_lengths
        self.values = {name: declare(self, name, self._default(name), setting.description,
                                     **descriptor(setting))
                       for name, setting in SETTINGS.items()}
        try:
            settings = self.config.with_link_biases(estimator_settings(self.values))
            self.pipeline = RangePipeline(self.config, PostureEstimator(
                self.model, moving_anchors=self.config.moving_anchor_indices, **settings))
            self.angle_samples = self._angle_samples(self.values)
        except ImportError as exc:
            raise StartupError(f'method: {exc}') from None
        except ValueError as exc:
            raise StartupError(parameter_name(str(exc))) from None
        compile_fit()       # before the first frame: the first compile takes seconds
        self.posture = self.create_publisher(PoseArray, POSTURE.name, POSTURE_QOS)
        self.markers = self.create_publisher(MarkerArray, MARKERS.name, POSTURE_QOS)
        self.joint_states = self.create_publisher(JointState, JOINT_STATES.name,
                                                  qos(JOINT_STATES))
        self.joint_names = joint_names(self.model.n_sections)
        self.description = self.create_publisher(String, ROBOT_DESCRIPTION.name,
                                                 qos(ROBOT_DESCRIPTION))
        self._publish_description()
        self.diagnostics = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name,
                                                 DIAGNOSTICS.depth)
        ranges_profile = self._ranges_profile(self.values['ranges_qos'])
        self.publish_markers = self.values['publish_markers']
        self.last_frame_time = None
        self.worst = None               # worst (level, message) since the last report
        self.status_name = f'{self.get_fully_qualified_name()}'
        self.worker = Worker('posture_estimator: frames', self._job_failed)
        self._closed = False
        self.create_subscription(JointState, RANGES.name, self.on_ranges, ranges_profile)
        self.angles_subscription = None
        self.next_estimator = None      # built by the check of a change of method
        self._subscribe_angles()
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.create_timer(1.0, lambda: self.worker.submit_urgent(self.publish_diagnostics))
        self.get_logger().info(f'{self.estimator.method} on {self.model.n_sections} '
                               f'sections, {self.model.n_anchors} anchors')

    @property
    def estimator(self):
        """Return the PostureEstimator the frames go to."""
        return self.pipeline.estimator

    @property
    def counts(self):
        """Return the frames by what became of them (``RangePipeline.counts``)."""
        return self.pipeline.counts

    @staticmethod
    def _ranges_profile(name):
        if name not in RANGES_INPUT_PROFILES:
            raise StartupError(f'ranges_qos: {name!r} is not one of '
                               f'{list(RANGES_INPUT_PROFILES)}')
        return RANGES_INPUT_PROFILES[name]

    def _default(self, name):
        if name == 'pitch_names':
            return [f'pitch{k}' for k in range(1, self.model.n_sections + 1)]
        return SETTINGS[name].default

    @property
    def angles(self):
        """Return the angle samples, when the method fuses angle sensors (else None)."""
        return self.angle_samples if _fuses_angles(self.estimator.method) else None

    def _angle_samples(self, values):
        pitch_names = list(values['pitch_names'])
        if len(pitch_names) != self.model.n_sections:
            raise ValueError(f'pitch_names: needs one name per section '
                             f'({self.model.n_sections}), got {pitch_names}')
        return AngleSamples(values['slew_name'], pitch_names, values['angle_max_age'])

    def _subscribe_angles(self):
        """Subscribe to the angle sensors once a method accepted fuses them."""
        if _fuses_angles(self.values['method']) and self.angles_subscription is None:
            self.angles_subscription = self.create_subscription(
                JointState, ANGLES.name, self.on_angles, RANGES_INPUT_QOS)

    # -- live parameters ------------------------------------------------------------------
    def _check_parameters(self, parameters):
        """Refuse what cannot change while running, or what would not start the node."""
        values = dict(self.values)
        for parameter in parameters:
            if parameter.name in PUMP_PARAMETERS:
                return SetParametersResult(successful=False, reason=(
                    f'{parameter.name} is read-only: the pump description is fixed at start'))
            if parameter.name == 'link_bias_std' and self.config.link_offset_std is not None:
                return SetParametersResult(successful=False, reason=(
                    'link_bias_std is read-only here: each link has its own from the pump '
                    "description's link_offset_std (calibrated)"))
            if parameter.name in SETTINGS:
                values[parameter.name] = parameter.value
        try:
            settings = self.config.with_link_biases(estimator_settings(values))
            self._angle_samples(values)
            # A new method is built here, where a failure can still refuse the change (the
            # SDP baseline needs cvxpy); the change, once accepted, takes it.
            self.next_estimator = None if settings['method'] == self.values['method'] \
                else PostureEstimator(self.model, moving_anchors=self.config.moving_anchor_indices,
                                      **settings)
        except ImportError as exc:
            return SetParametersResult(successful=False, reason=f'method: {exc}')
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=parameter_name(str(exc)))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        """Queue an accepted change behind the frames that came before it."""
        changed = {p.name: p.value for p in parameters if p.name in SETTINGS}
        if not changed:
            return
        self.values.update(changed)
        if 'max_angular_rate' in changed:           # the URDF's velocity limits
            self._publish_description()
        self._subscribe_angles()
        self.worker.submit(self._use_settings, dict(self.values), set(changed),
                           self.next_estimator)

    def _use_settings(self, values, changed, next_estimator):
        """From the next frame on: a new method starts cold, the rest keeps the warm start."""
        settings = self.config.with_link_biases(estimator_settings(values))
        method = settings.pop('method')
        if method != self.estimator.method:
            self.pipeline.estimator = next_estimator
            self.counts['method_changes'] += 1
            self.get_logger().info(f'method changed to {method}: starting cold')
        else:
            self.estimator.reconfigure(**settings)
        if 'angle_max_age' in changed:
            self.angle_samples = self._angle_samples(values)
        self.publish_markers = values['publish_markers']

    def _publish_description(self):
        """Publish the pump's URDF (latched), its joints' velocity limit the one in use."""
        text = urdf(self.config, self.values['max_angular_rate'])
        self.description.publish(String(data=text))

    # -- frames ---------------------------------------------------------------------------
    def on_angles(self, message):
        self.worker.submit(self._add_angles, message)

    def on_ranges(self, message):
        self.worker.submit(self._solve_frame, message)

    def _add_angles(self, message):
        if self.angles is not None:
            self.angles.add(to_seconds(message.header.stamp), message.name, message.position)

    def _solve_frame(self, message):
        try:
            self._on_ranges(message)
            # What the frame teaches changes only later frames: learned once it is out.
            self.estimator.settle()
        except Exception as exc:  # noqa: BLE001 - one bad frame must not stop the node
            self.counts['errors'] += 1
            self.estimator.reset()
            self.get_logger().error(f'frame dropped: {exc!r}', throttle_duration_sec=5.0)

    def _job_failed(self, exc):
        """Count and log a job of the worker that raised (a frame's are caught in it)."""
        self.counts['errors'] += 1
        self.get_logger().error(f'{exc!r}', throttle_duration_sec=5.0)

    def _on_ranges(self, message):
        stamp = to_seconds(message.header.stamp)
        slew, pitches = (None, None) if self.angles is None else self.angles.at(stamp)
        step = self.pipeline.step(stamp, message.name, message.position, message.effort,
                                  slew=slew, pitches=pitches)
        if step.diagnostics is not None:
            self.last_frame_time = self._now()
            self._keep_worst(step.diagnostics)
        if step.joints is None:
            return
        frame_id = message.header.frame_id or self.config.frame_id
        stamp = message.header.stamp                 # the frame's, exactly
        slew, pitches = step.angles
        pivot = self.model.pivot(slew)
        self.posture.publish(posture_message(pivot, step.joints, stamp, frame_id))
        self.joint_states.publish(JointState(
            header=message.header, name=self.joint_names,
            position=[float(v) for v in joint_positions(slew, pitches)]))
        if self.publish_markers:
            self.markers.publish(posture_markers(pivot, step.joints, stamp, frame_id))

    def _keep_worst(self, diagnostics):
        """Keep the worst frame since the last report, for ``/diagnostics``."""
        level, summary = grade(diagnostics)
        if self.worst is None or level > self.worst[0]:
            self.worst = (level, summary)

    def _now(self):
        """Return the node's time, seconds (simulated under use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def publish_diagnostics(self):
        diagnostics = self.estimator.last_diagnostics
        status = DiagnosticStatus(name=f'posture_estimator: {self.status_name}',
                                  hardware_id=pump_id(self, self.config.frame_id))
        silent = (None if self.last_frame_time is None
                  else self._now() - self.last_frame_time)
        if diagnostics is None:
            status.level, status.message = DiagnosticStatus.WARN, 'waiting for uwb/ranges'
            values = {'method': self.estimator.method}
        else:
            level, message, values = assess(diagnostics, self.lengths)
            if silent is not None and silent > SILENT_AFTER:
                status.level = DiagnosticStatus.ERROR
                status.message = f'no uwb/ranges for {silent:.1f} s'
            else:                           # the worst frame since the last report
                level, status.message = self.worst or (level, message)
                status.level = LEVELS[level]
        self.worst = None
        values['method'] = self.estimator.method
        values.update({f'frames {key}': str(value) for key, value in self.counts.items()})
        values['messages waiting'] = str(self.worker.waiting)
        if self.angles is not None:
            values.update({f'boom_angles {key}': str(value)
                           for key, value in self.angles.counts.items()})
        status.values = [KeyValue(key=key, value=value) for key, value in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = to_time(self._now())
        self.diagnostics.publish(array)

    def close(self):
        """Finish the frame being solved and start no other; once (``run_node`` may ask again)."""
        if self._closed:
            return
        self._closed = True
        left = self.worker.close()
        unsolved = sum(job == self._solve_frame for job, _ in left)
        if unsolved:
            self.get_logger().info(f'{unsolved} frame(s) left unsolved at shutdown')


def _fuses_angles(method):
    """Tell whether a method takes the angle sensors' readings."""
    return 'pitches' in METHODS[method].inputs


def main(args=None):
    return run_node(PostureEstimatorNode, args)


if __name__ == '__main__':
    sys.exit(main())
