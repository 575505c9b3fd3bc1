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

from glob import glob

from setuptools import find_packages, setup

package_name = 'epp_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=['epp_ros', 'epp_ros.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'pyserial', 'PyYAML', 'rich', 'rosbags',
                      'threadpoolctl', 'numba'],
    # test: what colcon test looks for to run pytest (the ament_python template's
    # tests_require, which setuptools 80 dropped). bench: the SDP baseline and the
    # benchmarks' plots (python3 dev.py bench); never needed at runtime.
    extras_require={'test': ['pytest', 'hypothesis', 'yourdfpy'],
                    'bench': ['cvxpy', 'matplotlib']},
    zip_safe=True,
    maintainer='epp_ros developers',
    maintainer_email='dev@epp-ros.invalid',
    description='Live boom posture of a concrete pump from UWB ranges (EPP/CEPP).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'uwb_driver = epp_ros.nodes.entry:uwb_driver',
            'posture_estimator = epp_ros.nodes.entry:posture_estimator',
            'uwb_emulator = epp_ros.nodes.entry:uwb_emulator',
            'epp_demo = epp_ros.cli.demo:main',
            'epp_bag = epp_ros.cli.bag:main',
            'epp_calibrate = epp_ros.cli.calibrate:main',
            'epp_urdf = epp_ros.cli.urdf:main',
        ],
    },
)
