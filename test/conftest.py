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

"""Test-session environment: private ROS log dir and reliable, local-only Fast DDS discovery."""
import os
from pathlib import Path
import random
import sys
import tempfile

HERE = Path(__file__).resolve().parent


def _configure_ros_environment():
    log_dir = tempfile.mkdtemp(prefix='epp_ros_test_log_')
    os.environ['ROS_LOG_DIR'] = log_dir
    os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(
        HERE.parent / 'config' / 'fastdds_fast_discovery.xml')
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    # A domain per run keeps parallel or leftover runs from hearing each other.
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
    os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)


_configure_ros_environment()


# Fixtures of the multi-process tests (imported here, after the environment is set).
from epp_ros.app.threads import single_blas_thread  # noqa: E402
from epp_ros.core import compile_fit  # noqa: E402
import pytest  # noqa: E402

# The numerics run as the nodes and tools run them, whatever test ran first: on one BLAS
# thread (a test that runs epp_bag's or the benchmarks' main would set it for all after it).
single_blas_thread()
# The kernels compiled (or loaded from numba's cache) before any test, so that no node's
# first frame waits for the compiler (about a minute on a fresh checkout).
compile_fit()

#: A test that uses one of these runs processes or speaks DDS: it is a system test.
SYSTEM_FIXTURES = {'processes', 'listener', 'fresh_listener', 'install'}


def pytest_collection_modifyitems(items):
    """Mark the tests under test/system/, and any test that starts processes, ``system``."""
    for item in items:
        if ('system' in Path(item.path).relative_to(HERE).parts[:1]
                or SYSTEM_FIXTURES & set(getattr(item, 'fixturenames', ()))):
            item.add_marker(pytest.mark.system)


@pytest.fixture(scope='module')
def listener():
    import rclpy
    from ros_processes import Listener
    rclpy.init()
    node = Listener()
    yield node
    node.destroy_node()
    rclpy.shutdown()


@pytest.fixture
def fresh_listener(listener):
    """Each test judges only what its own processes published."""
    listener.clear()
    return listener


@pytest.fixture
def processes():
    from ros_processes import Processes
    started = Processes()
    yield started
    started.stop_all()
