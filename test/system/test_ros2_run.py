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

"""The package as ROS users run it: built with colcon, found through the ament index."""
import importlib.util
import os
from pathlib import Path
import subprocess
import sys
import types
import xml.etree.ElementTree as ET

import pytest
import rclpy
from ros_processes import Listener, Processes, ROOT, script, start_emulator
import yaml

PYTHON = Path(sys.executable)


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    """Build a colcon workspace with epp_ros from this checkout."""
    workspace = tmp_path_factory.mktemp('ws')
    colcon = PYTHON.parent / 'colcon'
    result = subprocess.run(
        [str(colcon), '--log-base', str(workspace / 'log'), 'build', '--base-paths',
         str(ROOT), '--build-base', str(workspace / 'build'), '--install-base',
         str(workspace / 'install')], cwd=workspace, capture_output=True, text=True,
        timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return workspace / 'install'


def ros2_run_path(install, executable, env):
    """Return what `ros2 run epp_ros <executable>` executes: package prefix + lib/epp_ros/<exe>."""
    code = ('from ament_index_python.packages import get_package_prefix; '
            "print(get_package_prefix('epp_ros'))")
    prefix = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                            text=True, check=True).stdout.strip()
    return Path(prefix) / 'lib' / 'epp_ros' / executable


def installed_env(install):
    prefix = install / 'epp_ros'
    site = prefix / 'lib' / f'python{sys.version_info[0]}.{sys.version_info[1]}' / \
        'site-packages'
    env = dict(os.environ)
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), sys.prefix])
    env['PYTHONPATH'] = os.pathsep.join([str(site), env.get('PYTHONPATH', '')])
    return env


def test_install_layout(install):
    prefix = install / 'epp_ros'
    assert (prefix / 'share/ament_index/resource_index/packages/epp_ros').exists()
    assert (prefix / 'share/epp_ros/package.xml').exists()
    assert (prefix / 'share/epp_ros/config/pump.yaml').exists()
    assert (prefix / 'share/epp_ros/launch/epp.launch.py').exists()
    assert (prefix / 'share/epp_ros/rviz/epp.rviz').exists()
    for executable in ('uwb_driver', 'posture_estimator', 'uwb_emulator', 'epp_demo',
                       'epp_bag', 'epp_calibrate', 'epp_urdf'):
        assert os.access(prefix / 'lib/epp_ros' / executable, os.X_OK)


def test_installed_nodes_run_with_the_installed_config(install, tmp_path):
    env = installed_env(install)
    config = install / 'epp_ros/share/epp_ros/config/pump.yaml'
    driver = ros2_run_path(install, 'uwb_driver', env)
    estimator = ros2_run_path(install, 'posture_estimator', env)
    assert driver.parent == install / 'epp_ros/lib/epp_ros'
    processes = Processes()
    rclpy.init()
    listener = Listener('ros2_run_listener')
    try:
        link = str(tmp_path / 'ttyUWB')
        start_emulator(processes, 'json', ['--pty', '--link', link])
        for executable, extra in ((driver, ['-p', f'port:={link}']), (estimator, [])):
            processes.started.append(subprocess.Popen(
                [str(executable), '--ros-args', '--params-file', str(config), *extra],
                env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        # The installed estimator compiles its kernels on its first start (numba's cache
        # is per installed file): about a minute, more on a loaded machine.
        assert listener.spin_until(lambda: len(listener.postures) >= 5, 360), \
            [p.stderr.read() for p in processes.started[1:] if p.poll() is not None]
    finally:
        processes.stop_all()
        listener.destroy_node()
        rclpy.shutdown()


def test_installed_epp_urdf_writes_the_installed_pumps_urdf(install):
    """The command the launch file gives robot_state_publisher, as installed."""
    from epp_ros.app.config import load_pump_config
    from epp_ros.app.robot_description import urdf
    env = installed_env(install)
    config = install / 'epp_ros/share/epp_ros/config/pump.yaml'
    result = subprocess.run([str(ros2_run_path(install, 'epp_urdf', env)), str(config)],
                            env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout == urdf(load_pump_config(config), 0.35)


#: What ``colcon test`` runs here: real processes, a real parameters file, the lint, and the
#: test that the installed executables are the ones run (the whole suite takes too long).
COLCON_SUBSET = ('test_scripts_are_where_ros2_run_finds_them_when_installed or '
                 'test_unparsable_parameters_file_gives_one_line or test_package_xml or '
                 'test_levels_follow_the_thresholds')


def test_colcon_test_runs_the_packages_tests(install):
    """``colcon test`` after ``source install/setup.bash``: pytest, on what was installed."""
    workspace = install.parent
    results = workspace / 'test_results'
    result = subprocess.run(
        [str(PYTHON.parent / 'colcon'), '--log-base', str(workspace / 'log'), 'test',
         '--base-paths', str(ROOT), '--build-base', str(workspace / 'build'),
         '--install-base', str(install), '--test-result-base', str(results),
         '--return-code-on-test-failure', '--pytest-args', '-k', COLCON_SUBSET, '-p',
         'no:cacheprovider'], cwd=workspace, env=installed_env(install), capture_output=True,
        text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    suite = ET.parse(results / 'epp_ros' / 'pytest.xml').getroot()
    suite = suite if suite.tag == 'testsuite' else suite.find('testsuite')
    cases = {case.get('name').split('[')[0] for case in suite.iter('testcase')}
    assert 'test_scripts_are_where_ros2_run_finds_them_when_installed' in cases
    assert 'test_unparsable_parameters_file_gives_one_line' in cases
    assert int(suite.get('tests')) >= 14
    assert int(suite.get('failures')) == int(suite.get('errors')) == 0
    assert int(suite.get('skipped')) == 0


class _Recorder:
    """Stands in for a launch class: remembers its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


#: Where the stand-in ament index says epp_ros is installed.
EPP_PREFIX = '/opt/epp'


def prefix(name):
    """Stand-in get_package_prefix: only epp_ros is installed."""
    if name != 'epp_ros':
        raise LookupError(name)
    return EPP_PREFIX


def load_launch_file(monkeypatch, rviz_share, others=()):
    """
    Load the launch file under stand-ins (launch and launch_ros are not installable here).

    ``rviz_share`` is where get_package_share_directory finds rviz2, None: not installed;
    ``others``: other packages installed there too (robot_state_publisher).
    """
    modules = {
        'launch': types.SimpleNamespace(LaunchDescription=_Recorder),
        'launch.actions': types.SimpleNamespace(DeclareLaunchArgument=_Recorder,
                                                LogInfo=_Recorder),
        'launch.conditions': types.SimpleNamespace(IfCondition=_Recorder),
        'launch.substitutions': types.SimpleNamespace(LaunchConfiguration=_Recorder,
                                                      Command=_Recorder),
        'launch_ros': types.SimpleNamespace(),
        'launch_ros.actions': types.SimpleNamespace(Node=_Recorder),
        'launch_ros.parameter_descriptions': types.SimpleNamespace(ParameterValue=_Recorder),
    }
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    import ament_index_python.packages as packages

    def share(name):
        if name == 'epp_ros':
            return str(ROOT)
        if name in ('rviz2', *others) and rviz_share is not None:
            return rviz_share
        raise packages.PackageNotFoundError(name)
    monkeypatch.setattr(packages, 'get_package_share_directory', share)
    monkeypatch.setattr(packages, 'get_package_prefix', prefix)
    spec = importlib.util.spec_from_file_location('epp_launch', ROOT / 'launch/epp.launch.py')
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    return launch_file.generate_launch_description().args[0]


def launch_arguments(actions):
    return {a.args[0]: a.kwargs['default_value'] for a in actions
            if 'default_value' in a.kwargs}


def test_launch_file_names_what_exists(monkeypatch):
    actions = load_launch_file(monkeypatch, rviz_share=None)
    arguments = launch_arguments(actions)
    assert Path(arguments['config']).resolve() == ROOT / 'config/pump.yaml'
    nodes = [a.kwargs for a in actions if 'executable' in a.kwargs]
    assert [n['executable'] for n in nodes] == ['uwb_driver', 'posture_estimator']
    for node in nodes:
        assert node['package'] == 'epp_ros'
        assert Path(script(node['executable'])).exists()


def test_launch_file_puts_every_node_on_sim_time_on_request(monkeypatch, tmp_path):
    actions = load_launch_file(monkeypatch, rviz_share=str(tmp_path),
                               others=('robot_state_publisher',))
    assert launch_arguments(actions)['use_sim_time'] == 'false'
    nodes = [a.kwargs for a in actions if 'executable' in a.kwargs]
    assert [n['executable'] for n in nodes] == ['uwb_driver', 'posture_estimator',
                                                'robot_state_publisher', 'rviz2']
    for node in nodes:
        told = [p['use_sim_time'] for p in node['parameters']
                if isinstance(p, dict) and 'use_sim_time' in p]
        assert len(told) == 1 and told[0].args == ('use_sim_time',)


def rviz_condition(action):
    """Return the launch argument an action's IfCondition reads."""
    return action.kwargs['condition'].args[0].args[0]


def test_launch_file_starts_rviz_on_request_where_installed(monkeypatch, tmp_path):
    actions = load_launch_file(monkeypatch, rviz_share=str(tmp_path))
    assert launch_arguments(actions)['rviz'] == 'false'
    rviz = [a for a in actions if a.kwargs.get('executable') == 'rviz2']
    assert len(rviz) == 1 and rviz_condition(rviz[0]) == 'rviz'
    arguments = rviz[0].kwargs['arguments']
    config = Path(arguments[arguments.index('-d') + 1])
    assert config.resolve() == ROOT / 'rviz/epp.rviz'
    view = yaml.safe_load(config.read_text())['Visualization Manager']
    assert view['Global Options']['Fixed Frame'] == 'pump_base'
    shown = {d['Class']: d['Topic']['Value'] for d in view['Displays'] if 'Topic' in d}
    assert shown == {'rviz_default_plugins/MarkerArray': 'arm_posture/markers',
                     'rviz_default_plugins/PoseArray': 'arm_posture'}
    [model] = [d for d in view['Displays'] if d['Class'] == 'rviz_default_plugins/RobotModel']
    assert model['Description Source'] == 'Topic'
    assert model['Description Topic']['Value'] == 'robot_description'
    assert model['Description Topic']['Durability Policy'] == 'Transient Local'   # latched
    assert any(d['Class'] == 'rviz_default_plugins/TF' for d in view['Displays'])


def test_launch_file_works_without_rviz(monkeypatch):
    """rviz2 is not installed here: rviz:=true says so, the nodes start all the same."""
    actions = load_launch_file(monkeypatch, rviz_share=None)
    assert not any(a.kwargs.get('executable') == 'rviz2' for a in actions)
    notes = [a for a in actions if 'msg' in a.kwargs and 'rviz2' in a.kwargs['msg']]
    assert len(notes) == 1 and 'rviz2 is not installed' in notes[0].kwargs['msg']
    assert rviz_condition(notes[0]) == 'rviz'


def test_launch_file_starts_robot_state_publisher_with_the_configs_urdf(
        monkeypatch, tmp_path):
    actions = load_launch_file(monkeypatch, rviz_share=str(tmp_path),
                               others=('robot_state_publisher',))
    [publisher] = [a.kwargs for a in actions
                   if a.kwargs.get('executable') == 'robot_state_publisher']
    assert 'condition' not in publisher          # whenever it is installed
    [description] = [p['robot_description'] for p in publisher['parameters']
                     if 'robot_description' in p]
    assert description.kwargs == {'value_type': str}
    [command] = description.args
    executable, space, config = command.args[0]
    assert executable == f'{EPP_PREFIX}/lib/epp_ros/epp_urdf' and space == ' '
    assert config.args == ('config',)        # the same pump.yaml as the nodes'


def test_launch_file_says_when_robot_state_publisher_is_missing(monkeypatch, tmp_path):
    actions = load_launch_file(monkeypatch, rviz_share=str(tmp_path))
    assert not any(a.kwargs.get('executable') == 'robot_state_publisher' for a in actions)
    notes = [a.kwargs['msg'] for a in actions if 'msg' in a.kwargs]
    assert any('robot_state_publisher is not installed' in note for note in notes)
