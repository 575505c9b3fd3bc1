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

"""The kernels' switch: EPP_ROS_COMPILED=0 runs numpy alone, in a process of its own."""
import json
import os
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[4]
# A frame of each compiled method, then what the process imported.
PROBE = """
import json, sys
import numpy as np
from epp_ros.core import compile_fit, PostureEstimator
from epp_ros.core.simulation import truck_pump
from epp_ros.core.solvers import compiled
model = truck_pump()
ranges = model.ranges(model.forward_kinematics(0.3, np.radians([50, 20, 0, -20, -40])))
statuses = []
for method in ('chain', 'cepp', 'track'):
    estimator = PostureEstimator(model, method)
    estimator.update(ranges)
    statuses.append(estimator.last_diagnostics.status)
print(json.dumps({'switch': compiled.COMPILED, 'compiled': compile_fit(), 'statuses': statuses,
                  'numba': 'numba' in sys.modules,
                  'kernels': sorted(name for name in sys.modules if 'compiled_' in name)}))
"""

# After compile_fit, field frames of every compiled method (refused ones too), then which
# of the kernels' compiled functions took a new type of argument (numba compiles it then).
PROBE_TYPES = """
import json, sys
from numba.core.registry import CPUDispatcher
import numpy as np
from epp_ros.core import compile_fit, PostureEstimator
from epp_ros.core.simulation.simulate import (field_effects, make_motion, simulate_field,
                                              truck_pump)
compile_fit()
modules = [module for name, module in sys.modules.items() if 'compiled_' in name]
dispatchers = {f'{module.__name__}.{name}': value for module in modules
               for name, value in vars(module).items() if isinstance(value, CPUDispatcher)}
before = {name: len(value.signatures) for name, value in dispatchers.items()}
model = truck_pump()
rng = np.random.default_rng(4)
frames = simulate_field(model, make_motion('working', model, 6.0, rng), 6.0,
                        field_effects('real_uwb,tdma,dropouts'), rng)
for method in ('chain', 'cepp', 'track'):
    for lowest_joint in (-0.5, 10.0):
        estimator = PostureEstimator(model, method, lowest_joint=lowest_joint)
        for frame in frames:
            estimator.update(**frame.inputs())
print(json.dumps({'dispatchers': len(dispatchers), 'compiled again': sorted(
    name for name, value in dispatchers.items() if len(value.signatures) > before[name])}))
"""


def probe(code=PROBE, **environment):
    """Run ``code`` in a fresh interpreter with ``environment`` added; its report."""
    done = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env={**os.environ, **environment})
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_switch_off_runs_numpy_alone_and_never_imports_numba():
    report = probe(EPP_ROS_COMPILED='0')
    assert report == {'switch': False, 'compiled': False, 'statuses': ['ok'] * 3,
                      'numba': False, 'kernels': []}


def test_the_switch_on_imports_every_kernel():
    report = probe(EPP_ROS_COMPILED='1')         # numba is a requirement of the package
    assert report['switch'] and report['compiled'] and report['numba']
    assert report['statuses'] == ['ok'] * 3
    assert report['kernels'] == ['epp_ros.core.estimation.methods.compiled_chain',
                                 'epp_ros.core.model.compiled_boom',
                                 'epp_ros.core.model.compiled_bounds',
                                 'epp_ros.core.model.compiled_nlos',
                                 'epp_ros.core.model.compiled_plane',
                                 'epp_ros.core.solvers.compiled_points']


def test_no_frame_waits_for_the_compiler_after_compile_fit():
    report = probe(PROBE_TYPES, EPP_ROS_COMPILED='1')
    assert report['dispatchers'] >= 4
    assert report['compiled again'] == []
