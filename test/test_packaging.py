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
import xml.etree.ElementTree as ET

ROOT = Path(__file__).resolve().parents[1]
CONSOLE_SCRIPTS = {'uwb_driver', 'posture_estimator', 'uwb_emulator', 'epp_demo', 'epp_bench',
                   'epp_bag', 'epp_calibrate'}


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
