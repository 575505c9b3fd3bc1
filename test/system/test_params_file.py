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

"""A parameters file rcl cannot parse stops either node with one line and status 2."""
import subprocess

import pytest
from ros_processes import script

#: name -> (file content or None for a missing file, what the line must say)
BROKEN = {
    'malformed': ('/**:\n  ros__parameters:\n    base: [0.0, 0.0\n', 'not valid YAML'),
    'tab': ('/**:\n\tros__parameters:\n    frame_id: x\n', "'\\t'"),
    'top-level-list': ('- frame_id\n- pump_base\n', 'top level'),
    'no-ros-parameters': ('/**:\n  frame_id: pump_base\n', 'no ros__parameters'),
    'mixed-list': ('/**:\n  ros__parameters:\n    base: [0, 0.0, 3.5]\n',
                   'base: [0, 0.0, 3.5] mixes integers and floats'),
    'missing': (None, 'No such file'),
}


@pytest.mark.parametrize('node', ['uwb_driver', 'posture_estimator'])
@pytest.mark.parametrize('case', list(BROKEN))
def test_unparsable_parameters_file_gives_one_line(node, case, tmp_path):
    content, says = BROKEN[case]
    path = tmp_path / f'{case}.yaml'
    if content is not None:
        path.write_text(content)
    result = subprocess.run([script(node), '--ros-args', '--params-file', str(path)],
                            capture_output=True, text=True, timeout=60)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f'{node}: parameters file {path}: ')
    assert says in lines[0]


def test_other_ros_arguments_rcl_rejects_give_one_line():
    result = subprocess.run([script('uwb_driver'), '--ros-args', '-r', 'not a remap'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
