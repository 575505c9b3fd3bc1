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
Console scripts of the nodes: the stop request is taken before anything slow is imported.

A signal between the interpreter's start and the node's ``main`` would otherwise land in an
import and print a traceback; the node module is imported only once SIGINT and SIGTERM
merely request a shutdown (``stopping``), which ``run_node`` then honours.
"""
import importlib
import sys

from epp_ros.nodes.stopping import ignore_signals, shutdown_on_signals, ShutdownRequest


def _run(module):
    shutdown_on_signals()
    main = importlib.import_module(module).main
    if ShutdownRequest.requested:           # asked to stop while importing: nothing to do
        ignore_signals()                    # (the interpreter's exit restores the defaults)
        return 0
    return main()


def uwb_driver():
    """``uwb_driver``."""
    return _run('epp_ros.nodes.driver')


def posture_estimator():
    """``posture_estimator``."""
    return _run('epp_ros.nodes.estimator')


def uwb_emulator():
    """``uwb_emulator``."""
    return _run('epp_ros.nodes.emulator')


if __name__ == '__main__':
    sys.exit(globals()[sys.argv.pop(1)]())
