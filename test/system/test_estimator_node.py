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
posture_estimator in this process: its executor free while its worker solves a frame.

The node is spun on a thread as ``run_node`` spins it; the test speaks to it over DDS
from the listener and holds a frame open by blocking the estimator's update on an event.
"""
import threading

from builtin_interfaces.msg import Time
from epp_ros.app.contract import POSTURE, RANGES
from epp_ros.app.pipeline import Step
from epp_ros.nodes.messages import POSTURE_QOS, RANGES_QOS
from geometry_msgs.msg import PoseArray
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter, parameter_dict_from_yaml_file
from ros_processes import PUMP_YAML
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

TIMEOUT = 30.0
#: The node's namespace: apart from the other tests' processes.
NAMESPACE = '/in_process'


@pytest.fixture
def estimator_in_process(listener):
    """Run a posture_estimator in this process, spun on a thread as ``run_node`` spins it."""
    from epp_ros.nodes.estimator import PostureEstimatorNode
    from rclpy.executors import SingleThreadedExecutor
    pump = parameter_dict_from_yaml_file(str(PUMP_YAML), use_wildcard=True)
    node = PostureEstimatorNode(namespace=NAMESPACE, parameter_overrides=[
        Parameter.from_parameter_msg(message) for message in pump.values()])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()
    yield node
    node.close()
    executor.shutdown(timeout_sec=0)
    spinning.join(TIMEOUT)
    node.destroy_node()


def _set_parameters(listener, request):
    client = listener.create_client(SetParameters, f'{NAMESPACE}/posture_estimator/'
                                    'set_parameters')
    try:
        assert client.wait_for_service(timeout_sec=TIMEOUT)
        future = client.call_async(request)
        assert listener.spin_until(future.done, TIMEOUT)
        return future.result().results
    finally:
        listener.destroy_client(client)


def test_a_change_is_answered_while_a_frame_is_solved_and_applies_from_the_next(
        listener, estimator_in_process):
    """The executor answers while the node's worker solves; the change waits its turn."""
    node = estimator_in_process
    solving, release, seen = threading.Event(), threading.Event(), []

    def step(*args, **kwargs):                      # what each frame is solved with
        seen.append((node.estimator.method, node.publish_markers))
        solving.set()
        assert release.wait(TIMEOUT)
        return Step(None, None)

    node.pipeline.step = step
    ranges = listener.create_publisher(JointState, f'{NAMESPACE}/{RANGES.name}', RANGES_QOS)
    ranges.publish(JointState(header=Header(stamp=Time(sec=1)), name=['x'], position=[1.0]))
    assert listener.spin_until(solving.is_set, TIMEOUT)
    results = _set_parameters(listener, SetParameters.Request(parameters=[
        Parameter('method', value='chain').to_parameter_msg(),
        Parameter('publish_markers', value=False).to_parameter_msg()]))
    assert [r.successful for r in results] == [True, True]
    assert seen == [('cepp', True)]                 # answered with the frame still open
    release.set()
    ranges.publish(JointState(header=Header(stamp=Time(sec=2)), name=['x'], position=[2.0]))
    assert listener.spin_until(lambda: len(seen) == 2, TIMEOUT)
    assert seen == [('cepp', True), ('chain', False)]
    assert node.counts['method_changes'] == 1
    listener.destroy_publisher(ranges)


def test_a_frame_is_published_before_what_it_teaches_is_learned(listener, estimator_in_process):
    """The learners' work waits until the posture is out: it is not in the frame's latency."""
    node = estimator_in_process
    estimator, solve = node.estimator, node.pipeline.step
    events, learning, release = [], threading.Event(), threading.Event()
    settle = estimator.settle

    def step(*args, **kwargs):
        events.append('step')
        result = solve(*args, **kwargs)
        events.append('published' if result.joints is not None else 'refused')
        return result

    def settle_after_the_frame():
        if events and events[-1] == 'published' and not release.is_set():
            learning.set()                          # the node's, after a published frame
            assert release.wait(TIMEOUT)
        events.append('settled')
        settle()

    node.pipeline.step, estimator.settle = step, settle_after_the_frame
    postures = []
    listener.create_subscription(PoseArray, f'{NAMESPACE}/{POSTURE.name}', postures.append,
                                 POSTURE_QOS)
    ranges = listener.create_publisher(JointState, f'{NAMESPACE}/{RANGES.name}', RANGES_QOS)
    model = node.model
    distances = model.ranges(model.forward_kinematics(0.4, [0.6, 0.2, -0.1, -0.3, -0.5]))

    def judged(count):                              # frames judged and settled after
        outcomes = [event for event in events if event in ('published', 'refused')]
        return learning.is_set() or (len(outcomes) == count and events[-1] == 'settled')

    for k in range(1, 31):                          # one frame at a time, until one is out
        ranges.publish(JointState(header=Header(stamp=Time(sec=k)), name=node.config.link_names,
                                  position=distances.ravel().tolist()))
        assert listener.spin_until(lambda: judged(k), TIMEOUT)
        if learning.is_set():
            break
    assert learning.is_set(), f'no posture published in 30 exact frames: {events}'
    # The posture arrives while the estimator has yet to learn from its frame.
    assert listener.spin_until(lambda: postures, TIMEOUT)
    assert not release.is_set() and events[-1] == 'published'
    release.set()
    assert listener.spin_until(lambda: events[-1:] == ['settled'], TIMEOUT)
    listener.destroy_publisher(ranges)
