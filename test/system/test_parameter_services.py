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
The nodes through their real parameter services, as ``ros2 param`` uses them.

``dump`` and ``load`` below do what ros2param's verbs do (ros2cli is not on PyPI): dump
lists the parameters, gets them sorted by name and writes ``yaml.dump`` of
``{node: {ros__parameters: ...}}``; load sends a file's parameters in one SetParameters
request, which rclpy applies one parameter at a time, in the file's order.
"""
import os
import signal
import subprocess

from epp_ros.app.config import PUMP_PARAMETERS
import pytest
from rcl_interfaces.msg import Parameter as ParameterMessage, ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.parameter import Parameter, parameter_dict_from_yaml_file
from ros_processes import PUMP_YAML, script
import yaml

pytestmark = pytest.mark.usefixtures('fresh_listener')
TIMEOUT = 30.0
#: What a ParameterValue holds, by its type (as ros2param reads it).
FIELDS = {ParameterType.PARAMETER_BOOL: 'bool_value',
          ParameterType.PARAMETER_INTEGER: 'integer_value',
          ParameterType.PARAMETER_DOUBLE: 'double_value',
          ParameterType.PARAMETER_STRING: 'string_value',
          ParameterType.PARAMETER_BYTE_ARRAY: 'byte_array_value',
          ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
          ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
          ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
          ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value'}


def call(listener, service_type, service, request):
    """Call a node's service from the listener and return the response."""
    client = listener.create_client(service_type, service)
    try:
        assert client.wait_for_service(timeout_sec=TIMEOUT), service
        future = client.call_async(request)
        assert listener.spin_until(future.done, TIMEOUT), service
        return future.result()
    finally:
        listener.destroy_client(client)


def dump(listener, node):
    """Return the node's parameters as ``ros2 param dump`` writes them (YAML text)."""
    names = sorted(call(listener, ListParameters, f'{node}/list_parameters',
                        ListParameters.Request()).result.names)
    values = call(listener, GetParameters, f'{node}/get_parameters',
                  GetParameters.Request(names=names)).values
    parameters = {}
    for name, value in zip(names, values):
        field = FIELDS.get(value.type)
        held = None if field is None else getattr(value, field)
        parameters[name] = held if isinstance(held, (bool, int, float, str)) else list(held)
    return yaml.dump({node: {'ros__parameters': parameters}}, default_flow_style=False)


def load(listener, node, path):
    """Set a parameters file's values as ``ros2 param load``; (name, successful, reason)."""
    parameters = parameter_dict_from_yaml_file(str(path), target_nodes=[node])
    request = SetParameters.Request(parameters=list(parameters.values()))
    results = call(listener, SetParameters, f'{node}/set_parameters', request).results
    return [(name, r.successful, r.reason) for name, r in zip(parameters, results)]


def values(listener, node, names):
    """Get the current values of some parameters of a node."""
    response = call(listener, GetParameters, f'{node}/get_parameters',
                    GetParameters.Request(names=list(names)))
    return {name: Parameter.from_parameter_msg(ParameterMessage(name=name, value=value)).value
            for name, value in zip(names, response.values)}


def wait_for_node(listener, name):
    """Wait until a node of this name offers its parameter services."""
    client = listener.create_client(ListParameters, f'{name}/list_parameters')
    try:
        return client.wait_for_service(timeout_sec=TIMEOUT)
    finally:
        listener.destroy_client(client)


@pytest.fixture
def pty_port():
    """Open a pseudo-terminal for the driver to read: nothing is written to it."""
    master, slave = os.openpty()
    yield os.ttyname(slave)
    os.close(master)
    os.close(slave)


@pytest.mark.parametrize('node', ['posture_estimator', 'uwb_driver'])
def test_a_node_restarts_from_its_own_dump(listener, processes, pty_port, tmp_path, node):
    """``param dump`` writes ``[]`` for the empty offsets; rcl reads that as no value."""
    port = ['-p', f'port:={pty_port}'] if node == 'uwb_driver' else []
    first = processes([script(node), '--ros-args', '--params-file', str(PUMP_YAML), *port])
    assert wait_for_node(listener, f'/{node}'), first.stderr.read()
    dumped = dump(listener, f'/{node}')
    document = yaml.safe_load(dumped)[f'/{node}']['ros__parameters']
    assert document['anchor_offsets'] == [] and document['tag_offsets'] == []
    first.send_signal(signal.SIGINT)
    assert first.wait(TIMEOUT) == 0
    path = tmp_path / 'dump.yaml'
    path.write_text(dumped)
    second = processes([script(node), '--ros-args', '--params-file', str(path)])
    assert wait_for_node(listener, f'/{node}'), second.stderr.read()
    assert second.poll() is None
    assert dump(listener, f'/{node}') == dumped
    assert set(PUMP_PARAMETERS) <= set(document)


def test_load_applies_a_dumps_thresholds_in_its_order(listener, processes, tmp_path):
    """A warn/error pair is reached whatever the order the file gives it in."""
    processes([script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML)])
    assert wait_for_node(listener, '/posture_estimator')
    names = ('residual_error', 'residual_warn', 'predicted_rmse_error', 'predicted_rmse_warn')
    before = values(listener, '/posture_estimator', names)
    assert before['residual_warn'] > 0.4         # so error 0.4 comes below the warn first
    path = tmp_path / 'thresholds.yaml'
    path.write_text(yaml.dump({'/posture_estimator': {'ros__parameters': {
        'predicted_rmse_error': 0.3, 'predicted_rmse_warn': 0.1,
        'residual_error': 0.4, 'residual_warn': 0.2}}}))
    assert all(successful for _, successful, _ in load(listener, '/posture_estimator', path))
    assert values(listener, '/posture_estimator', names) == {
        'residual_error': 0.4, 'residual_warn': 0.2, 'predicted_rmse_error': 0.3,
        'predicted_rmse_warn': 0.1}


def test_a_method_that_cannot_be_built_is_refused_and_the_node_lives(
        listener, processes, tmp_path):
    """The SDP baseline needs cvxpy; without it ``param set method sdp`` is refused."""
    absent = tmp_path / 'without_cvxpy'
    (absent / 'cvxpy').mkdir(parents=True)
    (absent / 'cvxpy' / '__init__.py').write_text("raise ImportError('No module named cvxpy')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(absent), *filter(None, [os.environ.get('PYTHONPATH')])]))
    command = [script('posture_estimator'), '--ros-args', '--params-file', str(PUMP_YAML)]
    started = subprocess.run([*command, '-p', 'method:=sdp'], env=env, capture_output=True,
                             text=True, timeout=120)
    assert started.returncode == 2 and started.stderr.count('\n') == 1, started.stderr
    assert 'cvxpy' in started.stderr
    estimator = processes(command, env=env)
    assert wait_for_node(listener, '/posture_estimator'), estimator.stderr.read()
    request = SetParameters.Request(parameters=[
        Parameter('method', value='sdp').to_parameter_msg()])
    [refused] = call(listener, SetParameters, '/posture_estimator/set_parameters',
                     request).results
    assert not refused.successful and 'cvxpy' in refused.reason
    assert estimator.poll() is None
    assert values(listener, '/posture_estimator', ['method']) == {'method': 'cepp'}
    request.parameters[0].value.string_value = 'chain'
    [accepted] = call(listener, SetParameters, '/posture_estimator/set_parameters',
                      request).results
    assert accepted.successful
    assert values(listener, '/posture_estimator', ['method']) == {'method': 'chain'}
