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
A node's slow work on a thread of its own, one job at a time, in the order it came.

The executor's thread only queues: it stays free for the parameter services, so a
``set_parameters`` is answered while a frame is being solved, and a change queued behind
the frames that came before it applies from the next one. Not rclpy's
``MultiThreadedExecutor`` with callback groups: its ``shutdown`` does not wait for the
callbacks in flight (Jazzy), and a node destroyed under a running frame fails in it.
"""
import itertools
import queue
import threading

__all__ = ['Worker']

#: The entry that ends the worker: it goes before every job.
_STOP = (None, ())


class Worker:
    """
    Run jobs one at a time, in the order they were given, on a daemon thread.

    An urgent job (a report) goes before the others waiting, after the urgent ones.

    Parameters
    ----------
    name : str
        The thread's name.
    on_error : callable
        Called with the exception a job raised; the worker goes on with the next job.

    """

    def __init__(self, name, on_error):
        self._jobs = queue.PriorityQueue()      # (urgency, order, (job, args))
        self._order = itertools.count()
        self._on_error = on_error
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job, *args):
        """Queue ``job(*args)`` after every job given before it."""
        self._jobs.put((1, next(self._order), (job, args)))

    def submit_urgent(self, job, *args):
        """Queue ``job(*args)`` before the jobs waiting that are not urgent."""
        self._jobs.put((0, next(self._order), (job, args)))

    @property
    def waiting(self):
        """Return the number of jobs queued and not yet started."""
        return self._jobs.qsize()

    def close(self, timeout=10.0):
        """
        Let the job running finish (up to ``timeout`` s) and start no other.

        Returns
        -------
        list of (callable, tuple)
            The jobs queued that will not run, in their order.

        """
        self._closing.set()
        self._jobs.put((-1, next(self._order), _STOP))      # wakes a worker waiting
        self._thread.join(timeout)
        left = []
        while True:
            try:
                _, _, (job, args) = self._jobs.get_nowait()
            except queue.Empty:
                return left
            if job is not None:
                left.append((job, args))

    def _run(self):
        while not self._closing.is_set():
            _, _, (job, args) = self._jobs.get()
            if job is None or self._closing.is_set():
                break
            try:
                job(*args)
            except Exception as exc:  # noqa: BLE001 - one failed job must not stop the rest
                self._on_error(exc)
