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
The pump's URDF, read by an independent URDF library (yourdfpy).

Its forward kinematics at the joint positions published on ``joint_states`` must put every
joint where ``arm_posture`` says, for any pump description and posture.
"""
import dataclasses
import io
import subprocess

from epp_ros.app.config import load_pump_config
from epp_ros.app.contract import posture_poses
from epp_ros.app.pipeline import RangePipeline
from epp_ros.app.robot_description import joint_names, joint_positions, urdf
from epp_ros.core import PostureEstimator
from epp_ros.core.simulation.simulate import random_posture, RangeNoise
import numpy as np
import pytest
from ros_processes import PUMP_YAML, script
import yourdfpy

PUMP = load_pump_config(PUMP_YAML)
RATE = 0.35
#: Metres: forward kinematics of the URDF against the published joints.
EXACT = 1e-9


def parse(text):
    """Read the URDF with yourdfpy, which validates it too."""
    robot = yourdfpy.URDF.load(io.StringIO(text), build_collision_scene_graph=False,
                               load_meshes=False)
    assert robot.validate()
    return robot


def random_pump(rng, index):
    """Make a pump unlike the packaged one: sections, base, pivot, anchors, names."""
    p = int(rng.integers(2, 7))
    m = int(rng.integers(4, 9))
    anchors = np.c_[rng.uniform(-4, 4, (m, 2)), rng.uniform(0.5, 3.5, m)]
    anchors[:3, 2] = [0.5, 1.5, 3.0]            # not all in one plane
    return dataclasses.replace(
        PUMP, frame_id=f'truck{index}', arm_lengths=tuple(rng.uniform(3.0, 12.0, p)),
        base=tuple(np.r_[rng.uniform(-2, 2, 2), rng.uniform(2.0, 4.0)]),
        pivot_offset=float(rng.choice([0.0, rng.uniform(0.3, 1.5)])),
        tag_names=tuple(f'T{k}x{index}' for k in range(p)),
        tag_ids=tuple(f'{k:04X}' for k in range(p)),
        anchor_names=tuple(f'A{j}y{index}' for j in range(m)),
        anchor_ids=tuple(f'{j + 100:04X}' for j in range(m)),
        anchor_positions=tuple(map(tuple, anchors)), anchor_offsets=None, tag_offsets=None,
        pair_offsets=None, body_anchors=None)


PUMPS = [PUMP, *(random_pump(np.random.default_rng(seed), seed) for seed in range(4))]


def frames(robot, config, slew, pitches):
    """World positions of the tags and of the section frames' origins and x-axes."""
    robot.update_cfg(dict(zip(joint_names(len(pitches)), joint_positions(slew, pitches))))
    tags = np.array([robot.get_transform(f'tag_{name}', config.frame_id)[:3, 3]
                     for name in config.tag_names])
    sections = [robot.get_transform(f'boom{k}', config.frame_id)
                for k in range(1, len(pitches) + 1)]
    return tags, np.array([t[:3, 3] for t in sections]), np.array([t[:3, 0] for t in sections])


@pytest.mark.parametrize('config', PUMPS, ids=lambda c: c.frame_id)
def test_the_urdf_puts_the_boom_where_the_model_does(config):
    robot = parse(urdf(config, RATE))
    model = config.model()
    assert robot.actuated_joint_names == joint_names(model.n_sections)
    rng = np.random.default_rng(len(config.arm_lengths))
    for _ in range(10):
        slew, pitches, joints = random_posture(model, rng)
        tags, origins, _ = frames(robot, config, slew, pitches)
        np.testing.assert_allclose(tags, joints, rtol=0, atol=EXACT)
        np.testing.assert_allclose(origins[0], model.pivot(slew), rtol=0, atol=EXACT)
        tip = robot.get_transform('tip', config.frame_id)[:3, 3]
        np.testing.assert_allclose(tip, joints[-1], rtol=0, atol=EXACT)
    for name, position in zip(config.anchor_names, config.anchor_positions):
        placed = robot.get_transform(f'anchor_{name}', config.frame_id)[:3, 3]
        np.testing.assert_allclose(placed, position, rtol=0, atol=EXACT)
    for joint in robot.robot.joints:
        if joint.type == 'revolute':
            assert joint.limit.velocity == RATE
            assert (joint.limit.lower, joint.limit.upper) == (-np.pi, np.pi)


#: epp2 does not hold the sections' lengths (the rigid boom moves by its errors); on the
#: random pumps' anchors its frames are refused, on the packaged pump's they are published.
CASES = [*((config, method) for config in PUMPS for method in ('cepp', 'chain')),
         (PUMP, 'epp2')]


@pytest.mark.parametrize('config, method', CASES,
                         ids=[f'{c.frame_id}-{method}' for c, method in CASES])
def test_published_angles_put_every_joint_where_the_posture_says(config, method):
    """What the node publishes for a frame: arm_posture's poses and joint_states' angles."""
    model = config.model()
    robot = parse(urdf(config, RATE))
    pipeline = RangePipeline(config, PostureEstimator(model, method))
    rng = np.random.default_rng(7)
    published = 0
    for frame in range(12):
        slew, pitches, joints = random_posture(model, rng)
        ranges, _ = RangeNoise(sigma=0.05).apply(model.ranges(joints), rng)
        pipeline.estimator.reset()
        step = pipeline.step(100.0 + frame, config.link_names, ranges.ravel())
        if step.joints is None:
            continue
        published += 1
        estimated_slew, estimated_pitches = step.angles
        tags, origins, x_axes = frames(robot, config, estimated_slew, estimated_pitches)
        poses = posture_poses(model.pivot(estimated_slew), step.joints)
        positions = np.array([position for position, _ in poses])
        np.testing.assert_allclose(tags, positions[1:], rtol=0, atol=EXACT)
        np.testing.assert_allclose(origins, positions[:-1], rtol=0, atol=EXACT)
        for (_, quaternion), x_axis in zip(poses[1:], x_axes):   # x along each section
            x, y, z, w = quaternion
            along = [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)]
            np.testing.assert_allclose(along, x_axis, rtol=0, atol=1e-9)
    assert published >= 6


def test_epp_urdf_writes_what_the_estimator_publishes(tmp_path):
    out = tmp_path / 'boom.urdf'
    result = subprocess.run([script('epp_urdf'), str(PUMP_YAML), '-o', str(out)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert out.read_text() == urdf(PUMP, RATE)
    printed = subprocess.run([script('epp_urdf'), '--max-angular-rate', '0.2'],
                             capture_output=True, text=True, timeout=60)
    assert printed.returncode == 0 and printed.stdout == urdf(PUMP, 0.2)
    slower = tmp_path / 'slower.yaml'
    slower.write_text(PUMP_YAML.read_text().replace('max_angular_rate: 0.35',
                                                    'max_angular_rate: 0.15'))
    from_file = subprocess.run([script('epp_urdf'), str(slower)], capture_output=True,
                               text=True, timeout=60)
    assert from_file.returncode == 0 and from_file.stdout == urdf(PUMP, 0.15)
    for bad, says in (([str(tmp_path / 'missing.yaml')], 'missing.yaml'),
                      (['--max-angular-rate', 'nan'], 'max-angular-rate'),
                      ([str(PUMP_YAML), '-o', str(tmp_path / 'no' / 'dir.urdf')], 'dir.urdf')):
        failed = subprocess.run([script('epp_urdf'), *bad], capture_output=True, text=True,
                                timeout=60)
        assert failed.returncode == 2 and failed.stdout == ''
        assert failed.stderr.count('\n') == 1 and says in failed.stderr, failed.stderr


def test_the_estimator_publishes_its_urdf_latched_and_joint_states_with_each_posture(
        listener, processes):
    """A real node: a late subscriber gets the URDF, whose kinematics match arm_posture."""
    from epp_ros.nodes.messages import qos, RANGES_QOS, to_seconds, to_time
    from epp_ros.app import contract
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    from ros_processes import poses_to_joints, UNBIASED_ARGS
    listener.clear()
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML),
               *UNBIASED_ARGS])
    ranges = listener.create_publisher(JointState, 'uwb/ranges', RANGES_QOS)
    assert listener.spin_until(lambda: ranges.get_subscription_count() >= 1, 30)
    descriptions, joint_states = [], []
    subscriptions = [
        listener.create_subscription(String, contract.ROBOT_DESCRIPTION.name,
                                     descriptions.append, qos(contract.ROBOT_DESCRIPTION)),
        listener.create_subscription(JointState, contract.JOINT_STATES.name,
                                     joint_states.append, qos(contract.JOINT_STATES))]
    try:
        assert listener.spin_until(lambda: descriptions, 30)        # latched: sent before
        robot = parse(descriptions[-1].data)
        model = PUMP.model()
        rng = np.random.default_rng(3)
        start = 1000.0
        for frame in range(5):
            joints = random_posture(model, rng)[2]
            message = JointState(name=PUMP.link_names,
                                 position=[float(v) for v in model.ranges(joints).ravel()])
            message.header.stamp = to_time(start + 100.0 * frame)     # time to get there
            ranges.publish(message)
            assert listener.spin_until(lambda: len(joint_states) > frame
                                       and len(listener.postures) > frame, 30)
        for posture, state in zip(listener.postures, joint_states):
            assert to_seconds(state.header.stamp) == to_seconds(posture.header.stamp)
            assert list(state.name) == joint_names(model.n_sections)
            robot.update_cfg(dict(zip(state.name, state.position)))
            tags = np.array([robot.get_transform(f'tag_{name}', PUMP.frame_id)[:3, 3]
                             for name in PUMP.tag_names])
            np.testing.assert_allclose(tags, poses_to_joints(posture), rtol=0, atol=EXACT)
        set_rate = SetParameters.Request(parameters=[
            Parameter('max_angular_rate', value=0.2).to_parameter_msg()])
        client = listener.create_client(SetParameters, '/posture_estimator/set_parameters')
        assert client.wait_for_service(timeout_sec=30)
        future = client.call_async(set_rate)
        assert listener.spin_until(future.done, 30) and future.result().results[0].successful
        listener.destroy_client(client)
        assert listener.spin_until(lambda: len(descriptions) >= 2, 30)
        assert descriptions[-1].data == urdf(PUMP, 0.2)     # the limits follow the setting
    finally:
        for subscription in subscriptions:
            listener.destroy_subscription(subscription)
        listener.destroy_publisher(ranges)
