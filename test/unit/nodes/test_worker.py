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

"""The node's worker: jobs in their order, one at a time; a failure goes on; a close stops it."""
import threading

from epp_ros.nodes.worker import Worker

TIMEOUT = 30.0


def _worker(errors=None):
    return Worker('test worker', (errors if errors is not None else []).append)


def test_jobs_run_one_at_a_time_in_the_order_given():
    done, running, overlaps = [], [], []
    finished = threading.Event()

    def job(k):
        running.append(k)
        overlaps.append(len(running) > 1)
        done.append(k)
        running.remove(k)

    worker = _worker()
    for k in range(200):
        worker.submit(job, k)
    worker.submit(finished.set)
    assert finished.wait(TIMEOUT)
    assert done == list(range(200)) and not any(overlaps)
    assert worker.close() == []


def test_a_job_that_raises_is_reported_and_the_next_runs():
    errors, finished = [], threading.Event()
    worker = _worker(errors)
    worker.submit(lambda: 1 / 0)
    worker.submit(finished.set)
    assert finished.wait(TIMEOUT)
    assert [type(e) for e in errors] == [ZeroDivisionError]
    worker.close()


def test_the_submitter_is_not_held_by_a_running_job():
    started, release, finished = threading.Event(), threading.Event(), threading.Event()
    worker = _worker()
    worker.submit(lambda: (started.set(), release.wait(TIMEOUT)))
    assert started.wait(TIMEOUT)
    worker.submit(finished.set)             # returns while the first job still runs
    assert worker.waiting == 1 and not finished.is_set()
    release.set()
    assert finished.wait(TIMEOUT)
    worker.close()


def test_close_lets_the_running_job_finish_and_returns_the_jobs_that_will_not_run():
    started, ended = threading.Event(), []

    def slow():                     # still running when close is asked for
        started.set()
        worker._closing.wait(TIMEOUT)
        ended.append('slow')

    def never(k):
        ended.append(k)

    worker = _worker()
    worker.submit(slow)
    assert started.wait(TIMEOUT)
    worker.submit(never, 1)
    worker.submit(never, 2)
    left = worker.close(timeout=TIMEOUT)
    assert ended == ['slow']
    assert left == [(never, (1,)), (never, (2,))]


def test_a_closed_idle_worker_ends_its_thread():
    worker = _worker()
    assert worker.close(timeout=TIMEOUT) == []
    assert not worker._thread.is_alive()


def test_an_urgent_job_goes_before_the_others_waiting_but_after_the_urgent_ones():
    started, release, finished, done = (threading.Event(), threading.Event(),
                                        threading.Event(), [])
    worker = _worker()
    worker.submit(lambda: (started.set(), release.wait(TIMEOUT)))
    assert started.wait(TIMEOUT)
    for k in range(3):
        worker.submit(done.append, f'frame {k}')
    worker.submit_urgent(done.append, 'report 1')
    worker.submit_urgent(done.append, 'report 2')
    worker.submit(finished.set)
    release.set()
    assert finished.wait(TIMEOUT)
    assert done == ['report 1', 'report 2', 'frame 0', 'frame 1', 'frame 2']
    worker.close()
