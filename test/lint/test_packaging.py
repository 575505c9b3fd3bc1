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

"""The package is laid out as ament_python expects, and core stays free of ROS."""
import ast
import configparser
from pathlib import Path
import re
import sys
import xml.etree.ElementTree as ET

ROOT = Path(__file__).resolve().parents[2]
CONSOLE_SCRIPTS = {'uwb_driver', 'posture_estimator', 'uwb_emulator', 'epp_demo',
                   'epp_bag', 'epp_calibrate', 'epp_urdf'}
#: Python modules from PyPI: their pip name and rosdep key (None: a pip extra only). The
#: keys are rosdistro's python.yaml: python3-rosbags-pip from ros/rosdistro#37795,
#: python3-rich from #43386, python3-yourdfpy-pip from #41102, python3-hypothesis from
#: #23334.
THIRD_PARTY = {'numpy': ('numpy', 'python3-numpy'), 'scipy': ('scipy', 'python3-scipy'),
               'serial': ('pyserial', 'python3-serial'), 'yaml': ('PyYAML', 'python3-yaml'),
               'rich': ('rich', 'python3-rich'), 'rosbags': ('rosbags', 'python3-rosbags-pip'),
               'threadpoolctl': ('threadpoolctl', 'python3-threadpoolctl'),
               'numba': ('numba', 'python3-numba'),
               'pytest': ('pytest', 'python3-pytest'),
               'hypothesis': ('hypothesis', 'python3-hypothesis'),
               'yourdfpy': ('yourdfpy', 'python3-yourdfpy-pip'),
               'cvxpy': ('cvxpy', None), 'matplotlib': ('matplotlib', None)}


def test_core_imports_no_ros():
    for path in (ROOT / 'epp_ros' / 'core').rglob('*.py'):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ''] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert not re.match(r'(rclpy|rosidl|.*_msgs)\b', name), f'{path}: {name}'


def test_package_xml():
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.get('format') == '3' and root.findtext('name') == 'epp_ros'
    depends = {e.text for e in root.iter('depend')}
    assert {'rclpy', 'std_msgs', 'geometry_msgs', 'sensor_msgs', 'diagnostic_msgs',
            'visualization_msgs'} <= depends
    assert {'python3-numpy', 'python3-scipy', 'python3-serial'} <= {
        e.text for e in root.iter('exec_depend')}
    assert root.find('export/build_type').text == 'ament_python'


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    config = configparser.ConfigParser()
    config.read(ROOT / 'setup.cfg')
    assert config['develop']['script_dir'] == '$base/lib/epp_ros'
    assert config['install']['install_scripts'] == '$base/lib/epp_ros'
    assert (ROOT / 'resource' / 'epp_ros').exists()


def test_console_scripts_are_declared_and_importable():
    source = (ROOT / 'setup.py').read_text()
    declared = dict(re.findall(r"'(\w+) = ([\w.:]+)'", source))
    assert set(declared) == CONSOLE_SCRIPTS
    for target in declared.values():
        module, function = target.split(':')
        assert callable(getattr(__import__(module, fromlist=[function]), function))


def imported_modules(paths):
    """Top-level modules imported anywhere in these files (also inside functions)."""
    found = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                found.add(node.module.split('.')[0])
    local = {'epp_ros', 'benchmarks', *(path.stem for path in (ROOT / 'test').rglob('*.py'))}
    return found - set(sys.stdlib_module_names) - local


def declared():
    """package.xml's keys by kind, and setup.py's requirements by group."""
    root = ET.parse(ROOT / 'package.xml').getroot()
    keys = {kind: {e.text for e in root.iter(kind)}
            for kind in ('depend', 'exec_depend', 'test_depend')}
    tree = ast.parse((ROOT / 'setup.py').read_text())
    setup = next(node for node in ast.walk(tree) if isinstance(node, ast.Call)
                 and getattr(node.func, 'id', '') == 'setup')
    arguments = {k.arg: ast.literal_eval(k.value) for k in setup.keywords
                 if k.arg in ('install_requires', 'extras_require')}
    return keys, arguments['install_requires'], arguments['extras_require']


def test_every_import_is_declared_for_rosdep_and_pip():
    """What the package imports is a run dependency; what its tests import, a test one."""
    keys, install_requires, extras = declared()
    run_keys = keys['depend'] | keys['exec_depend']
    package = imported_modules([*(ROOT / 'epp_ros').rglob('*.py'),
                                *(ROOT / 'launch').glob('*.py')])
    tests = imported_modules((ROOT / 'test').rglob('*.py')) - package
    for module in sorted(package | tests):
        if module not in THIRD_PARTY:       # a ROS package: its key is its name
            wanted = run_keys if module in package else run_keys | keys['test_depend']
            assert module in wanted, f'{module}: not in package.xml'
            continue
        pip, key = THIRD_PARTY[module]
        if key is None:                     # optional: the benchmarks' extra
            assert pip in extras['bench'], f'{module}: not in extras_require bench'
        elif module in package:
            assert key in keys['exec_depend'], f'{module}: {key} not an exec_depend'
            assert pip in install_requires, f'{module}: {pip} not in install_requires'
        else:
            assert key in keys['test_depend'], f'{module}: {key} not a test_depend'
            assert pip in extras['test'], f'{module}: {pip} not in extras_require test'


def test_scripts_are_where_ros2_run_finds_them_when_installed():
    """Under colcon test (the install on the ament index) the tests run what it installed."""
    from ament_index_python.packages import get_package_prefix, PackageNotFoundError
    from ros_processes import BIN, EXECUTABLES, script
    try:
        installed = Path(get_package_prefix('epp_ros')) / 'lib' / 'epp_ros'
    except PackageNotFoundError:
        installed = None
    assert EXECUTABLES == (installed or BIN)
    assert Path(script('posture_estimator')).parent == EXECUTABLES
