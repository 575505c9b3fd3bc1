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
How a node is asked to stop: SIGINT and SIGTERM set a flag, whenever and however often.

Standard library only, so that the console scripts (``entry``) install it before the slow
imports of rclpy, numpy and scipy: a Ctrl-C during start-up must not end in a traceback.
"""
import signal

__all__ = ['ShutdownRequest', 'shutdown_on_signals', 'ignore_signals']


class ShutdownRequest:
    """
    Set by SIGINT and SIGTERM, however often and whenever they come; never raises.

    ``ros2 launch`` forwards a terminal's Ctrl-C as a second SIGINT (and SIGTERM after a
    timeout): a handler that raised (KeyboardInterrupt) would land in the cleanup of the
    first. A plain attribute, not a threading.Event: a signal handler that takes a lock the
    interrupted main thread holds would deadlock.
    """

    requested = False
    signals = 0

    @classmethod
    def handle(cls, signum, frame):
        cls.requested = True
        cls.signals += 1


def shutdown_on_signals():
    """
    From now on SIGINT and SIGTERM only request a shutdown; return the request.

    Call it before anything slow: a signal that arrives before it is installed still
    interrupts the process the Python way.
    """
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, ShutdownRequest.handle)
    return ShutdownRequest


def ignore_signals():
    """
    Ignore SIGINT and SIGTERM from now on, for a process that has shut down.

    Python's finalization puts back the default handlers of signals that have Python
    handlers (not of ignored ones): a second Ctrl-C while rclpy and Fast DDS tear down at
    exit would otherwise kill the process with status -2 after a clean shutdown.
    """
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
